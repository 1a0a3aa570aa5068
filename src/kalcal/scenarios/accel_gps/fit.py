"""Fit the accel-gps filter's noise and prior settings to one log by maximum likelihood.

The fit takes any log-likelihood of the log (:class:`AccelGpsLikelihood`: ``loglik(values)`` and
``calibrate(values)``), the reference one of :mod:`kalcal.scenarios.accel_gps.fit_reference` or a faster one
over the same log, and searches the free settings on a log scale (:mod:`kalcal.fitting.mle`) within a
factor :data:`RANGE` of their starts (a setting that is 0 starts from its :data:`FLOORS` value); the
latency on a linear scale within +-max(:data:`LINEAR`'s 0.5 s, |setting|), from its setting. The
fitted filter's innovation diagnostics (NIS and whiteness, :mod:`kalcal.calibration.diagnostics`) then
decide whether the model family is adequate for the log, with the NIS tail
(:mod:`kalcal.fitting.nis_tail`) on an ungated fit only; they are judged at the fitted point
(:func:`kalcal.fitting.result.fitted_point`: a ridge's members at the point the search reached on it).
A free latency that is not resolved (:mod:`kalcal.scenarios.accel_gps.latency_scan`) is held at its input, what
filter.toml runs, and the other free settings are refitted there; it does not by itself make the fit
inadequate (its note and ``notes`` say it is not resolved).
"""

from __future__ import annotations

import dataclasses
from dataclasses import replace
from collections.abc import Mapping, Sequence
from typing import Any, Protocol

import numpy as np

from kalcal.calibration.diagnostics import innovation_diagnostics
from kalcal.stats.nis import gate_excess
from kalcal.errors import KalcalError
from kalcal.scenarios.accel_gps import latency_scan
from kalcal.scenarios.accel_gps.evaluation import POSITION_FIX_KEYS
from kalcal.scenarios.accel_gps.fit_settings import filter_toml
from kalcal.fitting.mle import Free, maximize
from kalcal.fitting.nis_tail import nis_tail, not_applicable
from kalcal.fitting.result import FitParameter, FitResult, fitted_point
from kalcal.scenarios.accel_gps.settings import DENSITIES, DENSITY_UNITS, AccelGpsFilter, AccelGpsScenario, density_of, per_sample

DEFAULT_FREE = ("filter.accel_noise_density", "filter.bias_walk_density", "filter.gps_position_std", "filter.gps_velocity_std")
#: each per-sample noise key and the rate-free key the fit takes and writes in its place (a per-sample
#: value holds at one rate, a density at every rate: filter.toml holds densities only)
RATE_FREE = {f"filter.{name}": f"filter.{density}" for name, (density, _) in DENSITIES.items()}
#: what a free setting that is 0 starts from (bias_walk_std per sample in m/s^2, its density in
#: m/s^3/sqrt(Hz), times in s)
FLOORS = {
    "filter.bias_walk_std": 1e-5,
    "filter.bias_walk_density": 1e-4,
    "filter.bias_correlation_time": 30.0,
    "filter.scale_std": 1e-4,
}
#: a gate that rejects more than this share of the fixes is taken to hide a model that does not fit, not
#: to remove gross outliers: the fit is then not adequate (below it, an excess over the gate's own share
#: is reported in ``notes`` as outliers)
OUTLIER_SHARE = 0.1
#: each search range spans this factor either side of the start (log scale)
RANGE = 1e3
#: settings searched on a linear scale, within +-max(this, |setting|) about 0: a latency may be negative
LINEAR = {"filter.gps_latency": 0.5}
#: what a model that does not fit may lack, and the setting that would add it
CANDIDATES = (
    ("time-correlated GNSS errors", None),
    ("heavy-tailed GNSS errors (gross outliers: --gate)", None),
    ("a Gauss-Markov bias (filter.bias_correlation_time with filter.bias_std)", "filter.bias_correlation_time"),
    ("a scale factor (filter.scale_std)", "filter.scale_std"),
    ("GPS latency (filter.gps_latency)", "filter.gps_latency"),
    ("a drifting bias (filter.bias_walk_density)", "filter.bias_walk_density"),
)


class AccelGpsLikelihood(Protocol):
    """What the fit needs of a log: its log-likelihood and its calibration under given settings. ``loglik``
    may be called from several threads at once (:func:`kalcal.fitting.mle.maximize`)."""

    fixes: int

    def loglik(self, values: Mapping[str, float], *, gate: float | None = None, rejected: np.ndarray | None = None) -> float: ...

    def calibrate(self, values: Mapping[str, float], *, gate: float | None = None) -> Any: ...

    def settings_value(self, key: str) -> float: ...

    def unit(self, key: str) -> str: ...


class RateFreeLog:
    """A log's likelihood (:class:`AccelGpsLikelihood`) addressed by the rate-free noise keys as well:
    ``filter.accel_noise_density`` N is ``filter.accel_noise_std`` = N sqrt(rate) at the log's rate,
    ``filter.bias_walk_density`` K is ``filter.bias_walk_std`` = K / sqrt(rate)
    (:func:`kalcal.scenarios.accel_gps.settings.per_sample`). A search on a log scale is the same in either (the
    factor is fixed), so the estimate, its interval and log L convert exactly."""

    def __init__(self, log: AccelGpsLikelihood, rate: float) -> None:
        self.log, self.rate = log, float(rate)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.log, name)

    def _per_sample(self, values: Mapping[str, Any]) -> dict[str, Any]:
        out = {}
        for key, value in values.items():
            name = next((n for n, d in RATE_FREE.items() if d == key), None)
            out[name if name else key] = per_sample(name.split(".")[1], value, self.rate) if name else value
        return out

    def loglik(self, values: Mapping[str, float] = {}, **options) -> float:  # noqa: B006 (read only)
        return self.log.loglik(self._per_sample(values), **options)

    def calibrate(self, values: Mapping[str, float] = {}, **options) -> Any:  # noqa: B006 (read only)
        return self.log.calibrate(self._per_sample(values), **options)

    def settings_value(self, key: str) -> float:
        name = next((n for n, d in RATE_FREE.items() if d == key), None)
        if name is None:
            return self.log.settings_value(key)
        return density_of(name.split(".")[1], self.log.settings_value(name), self.rate)

    def unit(self, key: str) -> str:
        density = key.split(".", 1)[1]
        return DENSITY_UNITS[density] if key in RATE_FREE.values() else self.log.unit(key)


def rate_free(free: Sequence[str]) -> tuple[list[str], list[str]]:
    """``free`` with each per-sample noise key replaced by its density (:data:`RATE_FREE`), and a note
    for each replaced."""
    keys, notes = [], []
    for key in free:
        if key in RATE_FREE:
            notes.append(f"{key} fitted as {RATE_FREE[key]}, the rate-free setting filter.toml holds (its per-sample "
                         "value at the log's rate is in fit.json's per_sample)")
            key = RATE_FREE[key]
        if key not in keys:
            keys.append(key)
    return keys, notes


def default_free(position_std: bool = False, velocity_std: bool = False, *, positions: bool = True) -> list[str]:
    """:data:`DEFAULT_FREE`, with a multiplier on each per-fix std column the GPS log has instead of its
    constant; without ``filter.gps_position_std`` where the fixes have no position (``positions=False``,
    velocity-only fixes: nothing of the likelihood depends on it, so it has no estimate)."""
    free = list(DEFAULT_FREE)
    if not positions:
        free.remove("filter.gps_position_std")
    elif position_std:
        free[free.index("filter.gps_position_std")] = "log.position_std_multiplier"
    if velocity_std:
        free[free.index("filter.gps_velocity_std")] = "log.velocity_std_multiplier"
    return free


def inadequacy(verdict: str, free: Sequence[str]) -> str:
    """The sentence for a fit whose best settings still fail the diagnostics: the verdict and what may be missing."""
    missing = [text for text, key in CANDIDATES if key is None or key not in free]
    return (
        f"{verdict}. Even the best settings of this model leave the innovations inconsistent, so the model lacks "
        f"something; candidates: {', '.join(missing)}"
    )


def fit_accel_gps(
    log: AccelGpsLikelihood,
    scenario: AccelGpsScenario,
    free: Sequence[str] | None = None,
    *,
    profile: bool = False,
    gate: float | None = None,
    confidence: float = 0.95,
    rates: tuple[float, float] | None = None,
    std_medians: Mapping[str, float] | None = None,
    max_updates: int | None = None,
    options=None,
) -> FitResult:
    """Maximum-likelihood estimates of the ``free`` settings, their intervals and the fitted filter's adequacy.

    Parameters
    ----------
    log : AccelGpsLikelihood
    scenario : AccelGpsScenario
        The input settings (starts, and everything not free); filter.toml starts from them.
    free : sequence of str, optional
        ``filter.*`` settings and ``log.*_multiplier`` keys (default :data:`DEFAULT_FREE`).
    profile, confidence
        As :func:`kalcal.fitting.mle.maximize`.
    gate : float, optional
        The innovation gate's confidence, passed to the log's evaluations.
    rates : (float, float), optional
        The log's accelerometer and GPS rates, Hz, for filter.toml's [scenario].
    std_medians : mapping, optional
        The median of each per-fix std column (``{"position_std": m, "velocity_std": m/s}``), for the truth
        of a multiplier.
    max_updates : int, optional
        The most GPS intervals filter.toml's [scenario] duration may hold (verify's limit per realization).
    options : FitOptions, optional
        Its ``bootstrap`` (B), ``seed``, ``threads`` and ``client``: the parametric bootstrap
        (:mod:`kalcal.fitting.bootstrap`) over fixes drawn from the fitted filter over the log
        (:func:`kalcal.scenarios.accel_gps.resample.simulate_fixes`; ``log`` a prepared
        :class:`~kalcal.scenarios.accel_gps.log.AccelGpsLog`).
    """
    free, notes = rate_free(DEFAULT_FREE if free is None else free)
    # the noise at the log's own rate: the likelihood's per-sample settings, addressed by their densities
    rate = noise_rate(log, rates, scenario)
    log = RateFreeLog(log, rate)
    if "filter.bias_correlation_time" in free and "filter.bias_std" not in free:
        free.append("filter.bias_std")
        notes.append(
            "filter.bias_std freed with filter.bias_correlation_time: a Gauss-Markov bias's stationary std is its "
            "prior, which the log's prior rule does not make diffuse"
        )
    parameters = []
    for key in free:
        value = log.settings_value(key)
        if key in LINEAR:
            bound = max(LINEAR[key], abs(value))
            parameters.append(Free(key, value, -bound, bound, log.unit(key), scale="linear"))
            continue
        start = value if value > 0 else FLOORS.get(key, 1e-6)
        parameters.append(Free(key, start, start / RANGE, start * RANGE, log.unit(key)))
    imu_rate = rates[0] if rates is not None else scenario.scenario.imu_rate
    step = latency_scan.scan_step(imu_rate)
    markov = "filter.bias_correlation_time" in free or log.settings_value("filter.bias_correlation_time") > 0
    fit, calibration, mask, rounds = _search(log, parameters, gate, profile, confidence, step, notes, markov)
    held = _holds(fit)
    if held:
        # what filter.toml runs: the latency at its input; the others refitted there, so that the values,
        # intervals, log L, AIC and diagnostics are all of the written point
        fit, calibration, mask, rounds = _held(log, fit, [p for p in parameters if p.name != latency_scan.KEY], gate,
                                               profile, confidence, notes)
    chosen = fitted_point(fit)  # a ridge's members at the fitted point, so that adequacy is judged on the ridge
    used = _used(calibration)
    diagnostics = innovation_diagnostics(calibration.normalized_innovations[used], names=scenario.measurement_names)
    # the fit forces the mean NIS to p; the NIS tail's share it does not. A gate cuts that tail off
    tail = nis_tail(calibration.normalized_innovations[used]) if gate is None else None
    adequate = bool(diagnostics.consistent) and (tail is None or tail.passed)
    if adequate:
        adequacy = diagnostics.verdict
    else:
        failed = (None if diagnostics.consistent else diagnostics.verdict, tail.sentence() if tail is not None else None)
        # a latency held at its input is not fitted: it stays among the candidates the sentence names
        fitted_keys = [key for key in free if not (held and key == latency_scan.KEY)]
        adequacy = inadequacy("; ".join(text for text in failed if text), fitted_keys)
    if gate is not None:
        if rounds is None:
            notes.append(f"the gate's rejected set still changed after {MAX_GATE_ROUNDS} refits; the last set is used")
        rejected_count, gated = int(np.count_nonzero(mask)), int(np.count_nonzero(used) + np.count_nonzero(mask))
        excess = gate_excess(rejected_count, gated, gate)
        if excess and rejected_count > OUTLIER_SHARE * gated:
            adequate, adequacy = False, f"{excess}: no fit over the rest is trusted"
        elif excess:  # what a gate is for: a few gross outliers, counted and listed in rejected_fixes
            notes.append(f"{excess}: read as gross outliers (at most {OUTLIER_SHARE:.0%} of the fixes)")
    for key in free:
        if key.startswith("log."):
            column = key.split(".")[1].removesuffix("_multiplier")
            notes.append(f"{key}: the log's {column} column times one fitted multiplier, instead of a constant std")
    rejected = getattr(calibration, "rejected_rows", None)
    settings, comments, per_sample_values = filter_toml(scenario, chosen, fit, rates, std_medians or {}, max_updates, rate=rate)
    boot = _bootstrap(options, log, chosen, parameters, fit, None if gate is None else mask, confidence)
    return FitResult.from_search(
        scenario.NAME,
        fit,
        fixes=int(np.count_nonzero(used)),
        adequate=adequate,
        adequacy=adequacy,
        diagnostics={**diagnostics.as_dict(), "nis_tail": tail.as_dict() if tail is not None else not_applicable(gate)},
        notes=notes,
        rejected_fixes=None if gate is None else [int(row) for row in (rejected if rejected is not None else [])],
        settings=settings,
        comments=comments,
        confidence=confidence,
        extra={"bias": float(calibration.bias[-1]), "bias_std": float(calibration.std[-1, 2]), "per_sample": per_sample_values},
        derived=per_sample_parameters(fit.parameters, per_sample_values),
        bootstrap=boot,
    )


def _bootstrap(options, log: RateFreeLog, chosen: Mapping[str, float], parameters: Sequence[Free], fit, rejected,
               confidence: float):
    """The parametric bootstrap ``options`` ask for (None without one): each replicate's fixes drawn from the
    filter at the fitted point ``chosen`` over the prepared log (:func:`~kalcal.scenarios.accel_gps.resample.simulate_fixes`),
    refitted over the same fixes as the fit: with a gate, its ``rejected`` set is held out of every refit (the
    drawn fixes have no gross outliers to gate); ``confidence``: of the fit's intervals."""
    from kalcal.fitting.bootstrap import bootstrap_fit
    from kalcal.scenarios.accel_gps.log import AccelGpsLog
    from kalcal.scenarios.accel_gps.resample import simulate_fixes

    if not getattr(options, "bootstrap", 0):
        return None
    if not isinstance(log.log, AccelGpsLog):
        raise KalcalError("--bootstrap: needs the prepared accel-gps log (kalcal.scenarios.accel_gps.log), not "
                          f"{type(log.log).__name__}: its fixes are drawn over it")
    at = log._per_sample(chosen)

    def draw(rng):
        simulated = RateFreeLog(simulate_fixes(log.log, at, rng), log.rate)
        # a setting not refitted (unidentified, held) stays where the fixes were drawn from
        return lambda values: simulated.loglik({**chosen, **values}, rejected=rejected)

    return bootstrap_fit(options, draw, parameters, fit, confidence)


def per_sample_parameters(parameters: Mapping[str, FitParameter], per_sample_values: Mapping[str, Any]) -> dict[str, FitParameter]:
    """Each fitted density's per-sample std at the log's rate (fit.json's ``per_sample``), by the density's
    setting, for display under it (:attr:`~kalcal.fitting.result.FitResult.derived`): m/s^2 per sample at
    that rate, its interval the density's mapped, identified and at its bound as the density is."""
    rate = per_sample_values["rate"]
    derived = {}
    for name, (density, _) in DENSITIES.items():
        p = parameters.get(f"filter.{density}")
        if p is None:
            continue
        entry = per_sample_values[name]
        derived[f"filter.{density}"] = FitParameter(
            name=name, value=entry["value"], ci_low=entry["ci_low"], ci_high=entry["ci_high"],
            unit=f"m/s^2 per sample at {rate:.4g} Hz", start=entry["value"], identified=p.identified,
            at_bound=p.at_bound, trades_off=p.trades_off, held=p.held,
        )
    return derived


#: refits with the gate's rejected set held fixed before the fit gives up on a stable set
MAX_GATE_ROUNDS = 5


def _used(calibration) -> np.ndarray:
    """The fixes in the likelihood: not rejected, after the diffuse prior's ``skip``, (K,) bool."""
    used = np.ones(calibration.time.size, dtype=bool)
    if getattr(calibration, "rejected", None) is not None:
        used &= ~np.asarray(calibration.rejected, dtype=bool)
    used[: int(getattr(calibration, "skip", 0) or 0)] = False
    return used


def _held(log, fit, others, gate, profile, confidence, notes):
    """The fit with an unresolved latency held at its input (absent from the values: the log's own
    setting): the ``others`` refitted there (:func:`_search`), or, none free, log L at the input; the
    latency's parameter and scan kept from ``fit``. Returns what :func:`_search` returns."""
    key = latency_scan.KEY
    if others:
        held, calibration, mask, rounds = _search(log, others, gate, profile, confidence)
        notes.append(f"the other free settings are refitted with {key} at its input, what filter.toml runs")
    else:
        calibration = log.calibrate({}, gate=gate)
        mask = None if gate is None else np.asarray(calibration.rejected, dtype=bool)
        value = log.loglik({}) if mask is None else log.loglik({}, rejected=mask)
        # nothing is searched at the written point: no verdict of the discarded search carries over
        held, rounds = replace(fit, values={}, loglik=float(value), notes=(), converged=True,
                               message=f"nothing to search: {key} held at its input"), 0
    parameters = {name: fit.parameters[key] if name == key else held.parameters[name] for name in fit.parameters}
    return replace(held, parameters=parameters, curves={**held.curves, key: fit.curves[key]}), calibration, mask, rounds


def _search(log, parameters, gate, profile, confidence, step=None, notes=None, markov=False):
    """The fit over a fixed set of fixes: with a gate, gate with the start settings, fit with that
    rejected set held fixed, re-gate with the fitted settings and refit until the set stops changing
    (at most :data:`MAX_GATE_ROUNDS` fits). With a free latency and a grid ``step`` (s), the latency's
    range is scanned before the first fit and at the last one (:mod:`kalcal.scenarios.accel_gps.latency_scan`; a
    multimodal or unresolved latency is said in ``notes``; ``markov``: the model has a Gauss-Markov bias).
    Returns the fit, the fitted calibration, the rejected set and the rounds taken (None where the set
    never settled); the calibration is None where the latency is unresolved (held at its input:
    :func:`_held` refits and calibrates there)."""
    scanned = step is not None and any(p.name == latency_scan.KEY for p in parameters)
    setting = next((p.start for p in parameters if p.name == latency_scan.KEY), None)

    def search(fn, params):
        return maximize(fn, params, profile=profile, confidence=confidence)

    def judged(fn, fit, params):
        if not scanned:
            return fit
        refit = lambda start: search(fn, [replace(p, start=start) if p.name == latency_scan.KEY else p for p in params])  # noqa: E731
        fit, said = latency_scan.judge(fn, fit, params, step, confidence, refit, setting, markov)
        if said and notes is not None:
            notes.append(said)
        return fit

    chosen_of = fitted_point

    if gate is None:
        params = latency_scan.start_from_scan(log.loglik, parameters, step) if scanned else parameters
        fit = judged(log.loglik, search(log.loglik, params), params)
        return fit, None if _holds(fit) else log.calibrate(chosen_of(fit)), None, 0
    mask = np.asarray(log.calibrate({}, gate=gate).rejected, dtype=bool)
    for rounds in range(1, MAX_GATE_ROUNDS + 1):
        held = mask.copy()
        fn = lambda values, held=held: log.loglik(values, rejected=held)  # noqa: E731
        if rounds == 1 and scanned:
            parameters = latency_scan.start_from_scan(fn, parameters, step)
        fit = search(fn, parameters)
        calibration = log.calibrate(chosen_of(fit), gate=gate)
        new = np.asarray(calibration.rejected, dtype=bool)
        if np.array_equal(new, mask):
            break
        mask = new
    else:
        rounds = None
    if scanned:  # judged over the last held set; a restart's calibration re-gates with its settings
        before = fit
        fit = judged(fn, fit, parameters)
        if _holds(fit):  # the caller refits with the latency at its input (_held), and calibrates there
            return fit, None, mask, rounds
        if chosen_of(fit) != chosen_of(before):  # a restart
            calibration = log.calibrate(chosen_of(fit), gate=gate)
            mask = np.asarray(calibration.rejected, dtype=bool)
    return fit, calibration, mask, rounds


def _holds(fit) -> bool:
    """Whether ``fit`` holds an unresolved latency at its input (:func:`latency_scan.unresolved`)."""
    latency = fit.parameters.get(latency_scan.KEY)
    return latency is not None and latency_scan.unresolved(latency)


def noise_rate(log, rates: tuple[float, float] | None, scenario: AccelGpsScenario) -> float:
    """The rate (Hz) the log's per-sample noise settings hold at: its median accelerometer rate (the
    log's ``period``), else ``rates``' first, else ``scenario.imu_rate``."""
    period = getattr(log, "period", None)
    if isinstance(period, (int, float)) and period > 0:
        return 1.0 / float(period)
    return float(rates[0]) if rates is not None else float(scenario.scenario.imu_rate)


def log_rates(imu_time: np.ndarray, gps_time: np.ndarray) -> tuple[float, float]:
    """The logs' median rates, Hz."""
    return float(1.0 / np.median(np.diff(imu_time))), float(1.0 / np.median(np.diff(gps_time)))


def check_free(free: Sequence[str], *, position_std: bool, velocity_std: bool, positions: bool = True) -> None:
    """Refuse a key that the accel-gps filter has no setting for, a multiplier of a column the log lacks, or,
    with velocity-only fixes (``positions=False``), a setting of the position fix (the likelihood does not
    depend on it: a flat direction, no estimate)."""
    accepted = {f"filter.{f.name}" for f in dataclasses.fields(AccelGpsFilter)} - {"filter.position0_mean", "filter.velocity0_mean"}
    for key in rate_free(free)[0]:
        if not positions and key in POSITION_FIX_KEYS:
            raise KalcalError(f'--free: {key} is a setting of the position fix, which velocity-only fixes '
                              '(scenario.gps_fixes = "velocity") do not have: the likelihood does not depend on it')
        if key == "log.position_std_multiplier" and not position_std or key == "log.velocity_std_multiplier" and not velocity_std:
            raise KalcalError(f"--free: {key} needs the GPS log's {key.split('.')[1].removesuffix('_multiplier')} column")
        if key not in accepted and not key.startswith("log.") or key.startswith("log.") and not key.endswith("_std_multiplier"):
            raise KalcalError(
                f"--free: expected noise or prior settings of the accel-gps filter ({', '.join(sorted(accepted))}), got {key!r}"
            )
