"""``kalcal calibrate MODEL.toml --data LOG``: a model file's filter (and RTS smoother) over one logged sample.

The file is bound to the log (:func:`kalcal.scenarios.model_file.data.bind`: every generic check of a log,
the times, steps, non-numbers and the stds), the filter runs over every row
(:func:`kalcal.core.timevarying_filter.filter_model`, exact diffuse start for the file's ``diffuse``
states), and with ``smooth`` the RTS smoother after it (:func:`~kalcal.core.timevarying_filter.smooth`).

**estimates.csv** has one row per row of the log (every row, measured or not, so that it lines up with
the log row by row): ``time`` (s), each state's filtered estimate ``<state>`` and its 1-sigma
``<state>_std`` (the state's unit), each measurement's innovation ``<measurement>_innovation``
(r_j = z_j - H_j xbar_j, the measurement's unit) and its 1-sigma ``<measurement>_innovation_std``
(sqrt of S_j's diagonal), and ``nis`` (r_o^T S_oo^-1 r_o over the components measured at that row,
dimensionless); with ``smooth`` also ``<state>_smoothed`` and ``<state>_smoothed_std``. A row without a
measurement has NaN innovations and NIS. Before the diffuse period ends (the first row whose posterior
is proper) a diffuse state's estimate and sigma are NaN: it has no finite mean or variance yet (and the
smoothed ones are NaN there too: the exact diffuse smoother is not implemented).

**summary.json**: the settings (``model``, ``filter``, ``truth``, ``data``, as a model file's run writes
them), the final estimates, sigmas and covariance (at the log's last row), ``loglik`` (the conditional
log-likelihood: conditioned on the components that resolve the diffuse states, the kalcal convention of
:mod:`kalcal.core.timevarying_filter`) with ``diffuse_term`` beside it (statsmodels' exact diffuse llf is
``loglik + diffuse_term``), the innovation diagnostics (:func:`kalcal.calibration.diagnostics.innovation_diagnostics`
on the normalized innovations), the stability windows and the warnings.

**The diagnostics' series.** Over the rows after the diffuse period with a measurement, the normalized
innovation of row j is L_j^{-1} r_{j,o} (S_{j,oo} = L_j L_j^T, o the measured components). Where every
such row measures the same components, the series is (K, |o|), one column per measurement, as the
built-in calibrations test it. Where rows measure different components (a 200 Hz sensor and 1 Hz fixes
in one table), the rows' normalized components, in row order and within a row in h's order, form one
series (N, 1): for a consistent filter every entry is N(0, 1) and independent of every other (the
Cholesky factor in h's order gives the sequential update's scalar innovations), so the NIS and
Ljung-Box tests hold their size on it.

**The stability windows** (``--windows K``, :mod:`kalcal.calibration.windows`). The log's rows are split
into K runs of equal count; the filter runs on each from the file's prior mean with its covariance
widened to a diagonal of at least (:data:`~kalcal.calibration.windows.DIFFUSE` sqrt(K) times the whole
log's final sigma)^2 per state (the file's diffuse states stay diffuse), so that no window inherits
another's information. Window i's estimate x_i is at its last row e_i. The model carries x_i forward to
e_{i+1}: x(e_{i+1}) = Phi^n x(e_i) + c_i + n_i, n = e_{i+1} - e_i, c_i = sum_k Phi^(n-1-k) B u_(e_i+k)
(the known inputs), n_i ~ N(0, sum_k Phi^k Gamma W Gamma^T Phi^kT); the differences x_{i+1} - Phi^n x_i - c_i
are tested against their covariance (:func:`kalcal.calibration.stability.difference_statistic`; with
Phi = I, no process noise and no inputs the constant form, the weighted mean's). Every state is tested.
"""

from __future__ import annotations

import dataclasses
import shlex
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from kalcal.calibration.plausibility import CalibrationWarning
from kalcal.calibration.stability import Stability, Window, compare_windows, untested
from kalcal.calibration.windows import DIFFUSE, check_windows
from kalcal.errors import ConfigError, KalcalError
from kalcal.results.calibration import CalibrationResult

if TYPE_CHECKING:
    from kalcal.core.timevarying import TimeVaryingModel
    from kalcal.core.timevarying_filter import TimeVaryingRun
    from kalcal.scenarios.model_file.model import CustomModelScenario

__all__ = ["OUTPUT_NAMES", "ModelFileCalibrationResult", "calibrate_logs", "calibrate_model_file", "normalized_series"]

#: the files a model file's calibration writes
OUTPUT_NAMES = ("estimates.csv", "summary.json")
#: the calibrate options a model file takes (the rest belong to the built-in scenarios)
#: what summary.json says of the likelihood's convention
LOGLIK_CONVENTION = (
    "conditional: log p(the measured components after the diffuse start | the components that resolve the "
    "diffuse states), natural log; statsmodels' exact diffuse llf = loglik + diffuse_term"
)


def _std(cov: np.ndarray) -> np.ndarray:
    """The 1-sigma of each state, (..., d), from covariances (..., d, d); NaN stays NaN (diffuse)."""
    return np.sqrt(np.clip(np.diagonal(cov, axis1=-2, axis2=-1), 0.0, None))


def normalized_series(run: TimeVaryingRun, names: tuple[str, ...]) -> tuple[np.ndarray, tuple[str, ...], np.ndarray]:
    """The normalized innovations the diagnostics test (the module docstring's "diagnostics' series").

    Parameters
    ----------
    run : TimeVaryingRun
    names : tuple of str
        The p measurements' names.

    Returns
    -------
    series : ndarray, shape (K, c)
        Dimensionless, N(0, I) rows for a consistent filter: (K, |o|) where every used row measures the
        same components o, else (N, 1), every measured component of every used row.
    labels : tuple of str
        The series' columns (the measurements, or one label for the pooled series).
    rows : ndarray of int, shape (K,)
        The rows used: after the diffuse period (a finite NIS) with a measurement.
    """
    rows = np.flatnonzero(np.isfinite(run.nis))
    if rows.size == 0:
        return np.zeros((0, 1)), ("innovations",), rows
    measured = run.measured[rows]
    patterns = np.unique(measured, axis=0)
    pieces = []
    for pattern in patterns:
        at = np.flatnonzero(np.all(measured == pattern, axis=1))
        comps = np.flatnonzero(pattern)
        s = run.innovation_cov[np.ix_(rows[at], comps, comps)]
        r = run.residual[np.ix_(rows[at], comps)]
        lower = np.linalg.cholesky(0.5 * (s + np.swapaxes(s, 1, 2)))
        pieces.append((at, np.linalg.solve(lower, r[..., None])[..., 0]))
    if len(patterns) == 1:
        comps = np.flatnonzero(patterns[0])
        return pieces[0][1], tuple(names[c] for c in comps), rows
    per_row: list[np.ndarray] = [np.empty(0)] * rows.size
    for at, values in pieces:
        for k, i in enumerate(at):
            per_row[i] = values[k]
    label = f"{', '.join(names)} (pooled: rows measure different components)"
    return np.concatenate(per_row)[:, None], (label,), rows


def _carry(model: TimeVaryingModel, start: int, end: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Phi^n, c, Q): the model's map of the state at row ``start`` to row ``end`` (n = end - start steps):
    x_end = Phi^n x_start + c + noise, c the known inputs' part, Q the noise's covariance."""
    d = model.state_dim
    transition, offset, drift = np.eye(d), np.zeros(d), np.zeros((d, d))
    gq = model.gamma @ model.w @ model.gamma.T
    bu = model.u @ model.b.T if model.b.size else np.zeros((model.steps, d))
    for k in range(start, end):
        transition = model.phi @ transition
        offset = model.phi @ offset + bu[k]
        drift = model.phi @ drift @ model.phi.T + gq
    return transition, offset, 0.5 * (drift + drift.T)


def model_file_stability(
    model: TimeVaryingModel, z: np.ndarray, whole: TimeVaryingRun, names: tuple[str, ...], units: tuple[str, ...], windows: int
) -> Stability:
    """The windows' test of a bound model file (the module docstring's "stability windows")."""
    from kalcal.core.timevarying import TimeVaryingModel
    from kalcal.core.timevarying_filter import filter_model
    from kalcal.models.settings import SettingError

    count = check_windows(windows)
    dynamic = not (np.array_equal(model.phi, np.eye(model.state_dim)) and not np.any(model.gamma @ model.w @ model.gamma.T)
                   and not (model.b.size and np.any(model.u @ model.b.T)))  # fmt: skip
    kind = "transition (phi, w, known inputs)" if dynamic else "constant"
    prior = "each window from the file's prior mean with a diagonal covariance widened to the log's final sigmas (diffuse states diffuse)"
    if count == 1:
        return untested(names, units, (), kind, prior, "one window (--windows 1)")
    final = _std(whole.cov[-1])
    if not np.all(np.isfinite(final)):
        return untested(names, units, (), kind, prior, "the whole log leaves a diffuse state undetermined")
    widths = DIFFUSE * np.sqrt(count) * final
    base = np.diag(model.m0)
    m0 = np.diag(np.where(model.diffuse, 0.0, np.maximum(base, widths**2)))
    found: list[Window] = []
    ends: list[int] = []
    for i, rows in enumerate(np.array_split(np.arange(model.steps), count)):
        where = f"window {i + 1} of {count}"
        if rows.size < 2:
            return untested(names, units, found, kind, prior, f"{where} has {rows.size} row(s), fewer than 2")
        span = slice(int(rows[0]), int(rows[-1]) + 1)
        try:
            part = TimeVaryingModel(
                phi=model.phi, gamma=model.gamma, w=model.w, b=model.b, x0=model.x0, m0=m0, h=model.h[span], v=model.v[span],
                u=model.u[span], diffuse=model.diffuse, sample_period=model.sample_period, times=model.times[span],
            )  # fmt: skip
            run = filter_model(part, z[span])
        except (SettingError, np.linalg.LinAlgError) as exc:
            return untested(names, units, found, kind, prior, f"{where}: {exc}")
        x, p = run.state[-1], run.cov[-1]
        t0, t1 = float(model.times[rows[0]]), float(model.times[rows[-1]])
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(p))):
            return untested(names, units, found, kind, prior, f"{where} (t {t0:.6g} to {t1:.6g} s) leaves a diffuse state undetermined")
        found.append(Window(t0, t1, int(np.count_nonzero(run.measured)), x.copy(), p.copy()))
        ends.append(int(rows[-1]))
    if not dynamic:
        return _compared(found, names, units, kind, prior)
    carried = [_carry(model, a, b) for a, b in zip(ends[:-1], ends[1:])]
    # the inputs' part moved into the estimates (y_i = x_i - o_i, o_{i+1} = Phi_i o_i + c_i), so that the
    # differences y_{i+1} - Phi_i y_i are x_{i+1} - Phi_i x_i - c_i; the windows reported are the x_i
    shift = np.zeros(model.state_dim)
    shifted = [found[0]]
    for (transition, offset, _), window in zip(carried, found[1:]):
        shift = transition @ shift + offset
        shifted.append(dataclasses.replace(window, estimate=window.estimate - shift))
    transitions = np.stack([c[0] for c in carried])
    drift = np.stack([c[2] for c in carried])
    stability = _compared(shifted, names, units, kind, prior, transitions, drift)
    return dataclasses.replace(stability, windows=tuple(found))


def _compared(found, names, units, kind, prior, transitions=None, drift=None) -> Stability:
    try:
        return compare_windows(found, names, units, model=kind, prior=prior, transitions=transitions, drift=drift)
    except np.linalg.LinAlgError:
        why = "the windows' covariance is singular (a state the windows know exactly): no chi-square test"
        return untested(names, units, found, kind, prior, why)


def _column_names(state_names, measurement_names, smooth: bool) -> list[str]:
    names = ["time", *state_names, *(f"{s}_std" for s in state_names)]
    names += [f"{m}_innovation{suffix}" for m in measurement_names for suffix in ("", "_std")] + ["nis"]
    if smooth:
        names += [f"{s}_smoothed{suffix}" for s in state_names for suffix in ("", "_std")]
    return names


def calibrate_model_file(
    scenario: CustomModelScenario, log: Any, *, smooth: bool = False, windows: int = 2, topic: str | None = None
) -> ModelFileCalibrationResult:
    """The model file's filter over one log; nothing is written (:meth:`ModelFileCalibrationResult.save`).

    Parameters
    ----------
    scenario : CustomModelScenario
        A model file with a ``[data]`` table.
    log : path or DataFrame
        Any log :func:`kalcal.io.logs.read_table` reads, one row per model step.
    smooth : bool
        Also the RTS-smoothed states (``<state>_smoothed``, ``<state>_smoothed_std``).
    windows : int
        The stability test's windows (1: none).
    topic : str, optional
        A bag's or ULog's topic.

    Raises
    ------
    ConfigError, DataError
        One line: a file without [data], a column missing or not numeric, a step off sample_period, ...
    """
    from kalcal.calibration.diagnostics import innovation_diagnostics
    from kalcal.core.timevarying_filter import filter_model
    from kalcal.core.timevarying_filter import smooth as rts
    from kalcal.io.logs import is_frame
    from kalcal.io.outputs import mark_inputs
    from kalcal.models.config import section_values

    windows = check_windows(windows)
    info = scenario.model
    states, measurements = info.state_names, info.measurement_names
    names = _column_names(states, measurements, smooth)
    clash = sorted({n for n in names if names.count(n) > 1})
    if clash:
        raise ConfigError(f"{info.file}: estimates.csv would have the column {clash[0]!r} twice: rename the state or measurement")
    bound = scenario.bind(log, topic=topic)
    model = bound.filter
    run = filter_model(model, bound.z)
    std = _std(run.cov)
    s_std = _std(run.innovation_cov)
    columns: dict[str, np.ndarray] = {"time": bound.times}
    columns.update({name: run.state[:, i] for i, name in enumerate(states)})
    columns.update({f"{name}_std": std[:, i] for i, name in enumerate(states)})
    for i, name in enumerate(measurements):
        columns[f"{name}_innovation"] = run.residual[:, i]
        columns[f"{name}_innovation_std"] = np.where(np.isfinite(run.residual[:, i]), s_std[:, i], np.nan)
    columns["nis"] = run.nis
    smoothed = None
    if smooth:
        smoothed = rts(run, model)
        smoothed_std = _std(smoothed.cov)
        for i, name in enumerate(states):
            columns[f"{name}_smoothed"] = smoothed.state[:, i]
            columns[f"{name}_smoothed_std"] = smoothed_std[:, i]

    series, labels, used = normalized_series(run, measurements)
    if used.size:
        diagnostics = innovation_diagnostics(series, names=labels).as_dict()
    else:
        diagnostics = {"fixes": 0, "consistent": False, "pvalue": float("nan"),
                       "verdict": "no measured row after the diffuse period: nothing to test"}  # fmt: skip
    diagnostics["series"] = list(labels)
    diagnostics["rows_used"] = int(used.size)
    units = tuple(info.state_units)
    stability = model_file_stability(model, bound.z, run, states, units, windows)

    warnings: list[CalibrationWarning] = []
    final, final_std = run.state[-1], std[-1]
    undetermined = [name for name, value in zip(states, final) if not np.isfinite(value)]
    if undetermined:
        warnings.append(CalibrationWarning(
            "diffuse-unresolved", f"{bound.source}: the log never determines {', '.join(undetermined)} (started diffuse): "
            "no finite estimate or sigma for it"))  # fmt: skip
    given = np.isfinite(bound.z)
    skipped = int(np.count_nonzero(given & ~run.measured))
    if skipped:
        warnings.append(CalibrationWarning(
            "measurements-skipped", f"{bound.source}: {skipped} measurement(s) skipped: the data column their row of h "
            "names is empty there"))  # fmt: skip
    from kalcal.scenarios.model_file.fit import likelihood_refusal

    # a log that gives the likelihood nothing (no measurement, or every one conditioned on by the diffuse
    # start) or a single row: the filter's estimates stand, but nothing tests the noise settings and
    # kalcal fit refuses the log, so it is not offered as the next step
    unfittable = likelihood_refusal(scenario, bound, run)
    if unfittable:
        warnings.append(CalibrationWarning("nothing-to-fit", f"{bound.source}: {unfittable} (kalcal fit refuses this log)"))
    elif not used.size:
        warnings.append(CalibrationWarning("no-innovations", f"{bound.source}: {diagnostics['verdict']}"))
    reasons = []
    if not used.size:
        reasons.append("the log has no measurement after the diffuse period to test them against")
    elif not diagnostics["consistent"]:
        reasons.append(f"the diagnostics say inconsistent ({diagnostics['verdict']})")
    if stability.stable is False:
        reasons.append("the windows' estimates disagree (stability: NOT stable)")
    because = " and ".join(reasons) or None
    if because and unfittable:
        warnings.append(CalibrationWarning(
            "sigma-untrusted", f"the states' 1-sigmas are NOT trusted: they hold only for a model and noise settings "
            f"that fit the log, and {because}"))  # fmt: skip
    elif because:
        # the log's path as given (a bag's or ULog's: its topic is in the model's TOPIC.FIELD columns), not
        # bound.source's "FILE topic TOPIC", which names it in messages
        data = shlex.quote(str(log)) if isinstance(log, (str, Path)) else "LOG"
        # runnable as printed: --free left at its default (w's and v's diagonal), named after it
        fit = f"kalcal fit {shlex.quote(str(info.file))} --data {data} --out fit"
        warnings.append(CalibrationWarning(
            "sigma-untrusted", f"the states' 1-sigmas are NOT trusted: they hold only for a model and noise settings "
            f"that fit the log, and {because}. Next: fit the noise settings to this log, `{fit}` (--free KEYS to "
            "choose others than w's and v's diagonal), then calibrate again with fit/model.toml"))  # fmt: skip

    result = ModelFileCalibrationResult(
        scenario=scenario.NAME, bias=float("nan"), bias_std=float("nan"), scale=None, scale_std=None,
        covariance=run.cov[-1], covariance_states=tuple(states), diagnostics=diagnostics,
        warnings=[w.as_dict() for w in warnings], columns=columns, time=float(bound.times[-1]),
        units={"time": "s", **dict(zip(states, units))}, stability_test=stability, sigma_trusted=because is None,
        run=run, smoothed=smoothed, settings=section_values(scenario), data=bound.source, name=info.name,
        file=str(info.file), state_names=tuple(states), measurement_names=tuple(measurements),
        measurement_units=tuple(info.measurement_units), estimate=final, estimate_std=final_std,
        sigma_untrusted_because=because, table_columns=bound.table.columns,
    )  # fmt: skip
    return result if is_frame(log) else mark_inputs(result, log)


@dataclass(frozen=True, repr=False, eq=False, kw_only=True)
class ModelFileCalibrationResult(CalibrationResult):
    """A model file's calibration: every state's estimate and 1-sigma at the log's last row (the base's
    ``bias`` and ``scale`` are not a model file's: NaN and None; :attr:`estimate` and :attr:`params` are its
    estimates), the run, the log-likelihood and its diffuse term.

    Attributes
    ----------
    run : TimeVaryingRun
        The filter over every row (:class:`kalcal.core.timevarying_filter.TimeVaryingRun`).
    smoothed : SmoothedRun or None
        The RTS smoother's, with ``smooth``.
    settings : dict
        The file's settings by section (``summary.json``'s ``settings``).
    data : str
        The log's name.
    name, file : str
        The model's name and its file.
    state_names, measurement_names, measurement_units : tuple of str
    estimate, estimate_std : ndarray, shape (d,)
        The final estimate and 1-sigma (the states' units; NaN for a state the log never determines).
    sigma_untrusted_because : str or None
    table_columns : tuple of str
        The log's columns the file read.
    """

    run: Any
    smoothed: Any
    settings: dict
    data: str
    name: str
    file: str
    state_names: tuple
    measurement_names: tuple
    measurement_units: tuple
    estimate: np.ndarray
    estimate_std: np.ndarray
    sigma_untrusted_because: str | None = None
    table_columns: tuple = ()

    OUTPUT_NAMES = OUTPUT_NAMES

    @property
    def loglik(self) -> float:
        """The conditional log-likelihood (natural log; :data:`LOGLIK_CONVENTION`)."""
        return float(self.run.loglik)

    @property
    def diffuse_term(self) -> float:
        """statsmodels' exact diffuse llf minus :attr:`loglik`."""
        return float(self.run.diffuse_term)

    def _summary(self) -> dict[str, Any]:
        run, states = self.run, self.state_names
        proper = int(run.proper_from)
        times = self.columns["time"]
        return {
            "scenario": self.scenario,
            "model": self.name,
            "settings": self.settings,
            "data": self.data,
            "columns": list(self.table_columns),
            "rows": int(run.state.shape[0]),
            "measurements_used": int(np.count_nonzero(run.measured)),
            "time": self.time,
            "states": list(states),
            "estimate": dict(zip(states, map(float, self.estimate))),
            "std": dict(zip(states, map(float, self.estimate_std))),
            "covariance": self.covariance,
            "sigma_trusted": self.sigma_trusted,
            **({"sigma_untrusted_because": self.sigma_untrusted_because} if self.sigma_untrusted_because else {}),
            "loglik": self.loglik,
            "diffuse_term": self.diffuse_term,
            "loglik_convention": LOGLIK_CONVENTION,
            "proper_from": {"row": proper, "time": float(times[proper]) if proper < times.size else None},
            "conditioned": int(np.count_nonzero(run.conditioned)),
            "smoothed": self.smoothed is not None,
            "diagnostics": self.diagnostics,
            "stability": self.stability,
            "warnings": self.warnings,
            "units": {**self.units, **{f"{m}": u for m, u in zip(self.measurement_names, self.measurement_units)}},
        }

    def _estimates(self) -> dict[str, tuple[float, float, bool]]:
        return {name: (float(x), float(s), bool(self.sigma_trusted))
                for name, x, s in zip(self.state_names, self.estimate, self.estimate_std)}  # fmt: skip

    def title(self) -> tuple[str, str]:
        used = int(np.count_nonzero(self.run.measured))
        return f"kalcal calibrate {self.name}: {self.run.state.shape[0]} rows, {used} measurements", f"t = {self.time:g} s"

    def lines(self) -> list[tuple[str, bool | None]]:
        if not np.any(self.run.measured & ~self.run.conditioned):
            return [("log-likelihood 0: no measurement in it (the empty sum, not a fit)", None)]
        if not np.any(self.run.conditioned):
            return [(f"log-likelihood {self.loglik:.10g}", None)]
        return [(f"log-likelihood {self.loglik:.10g} (conditional on the {int(np.count_nonzero(self.run.conditioned))} "
                 f"measurement(s) that resolve the diffuse start; diffuse_term {self.diffuse_term:.6g})", None)]  # fmt: skip

    def diagnostics_line(self) -> tuple[str, bool] | None:
        return str(self.diagnostics["verdict"]), bool(self.diagnostics["consistent"])

    def _repr_html_(self) -> str:
        from kalcal.results._display import html_facts, html_table

        ci = self._conf_int_quiet()
        rows = [[name, value, sigma, ci.loc[name, "lower"], ci.loc[name, "upper"], "yes" if trusted else "NO"]
                for name, (value, sigma, trusted) in self._estimates().items()]  # fmt: skip
        facts = html_facts(f"kalcal calibrate {self.name}", [
            ("log-likelihood", self.loglik), ("consistent", self.diagnostics.get("consistent")),
            ("warnings", len(self.warnings))])  # fmt: skip
        table = html_table(["state", "value", "sigma", "[0.025", "0.975]", "sigma trusted"], rows)
        import html

        notes = "".join(f"<li>{html.escape(str(w['code']))}: {html.escape(str(w['message']))}</li>" for w in self.warnings)
        return f"<div>{facts}{table}" + (f"<ul>{notes}</ul>" if notes else "") + "</div>"

    def __repr__(self) -> str:
        shown = ", ".join(f"{n}={x:.6g} ± {s:.3g}" for n, x, s in zip(self.state_names, self.estimate, self.estimate_std))
        trust = "" if self.sigma_trusted else " (sigmas NOT trusted)"
        return f"CalibrationResult({self.name}: {shown}{trust}, loglik={self.loglik:.6g}, warnings={len(self.warnings)})"


def _data_of(scenario: CustomModelScenario, logs: dict[str, Any], command: str):
    """The ``data`` log of ``logs``; none, or accel-gps's logs, refused in one line."""
    if logs.get("imu") is not None or logs.get("gps") is not None:
        raise KalcalError(f"--imu/--gps: not used by {scenario.label} (it reads --data)")
    if logs.get("data") is None:
        raise KalcalError(f"--data: required to {command} {scenario.label} (a log in its [data] layout)")
    return logs["data"]


def calibrate_logs(scenario: CustomModelScenario, logs: dict[str, Any], options) -> ModelFileCalibrationResult:
    """:meth:`CustomModelScenario.calibrate`: the options checked (those of the built-ins refused in one
    line), the log required, then :func:`calibrate_model_file`."""
    from kalcal.scenarios.protocol import require

    require(scenario, "calibrate")
    options.refuse_unless(scenario.label, scenario.CALIBRATE_OPTIONS)
    data = _data_of(scenario, logs, "calibrate")
    return calibrate_model_file(scenario, data, smooth=options.smooth, windows=options.windows, topic=logs.get("topic"))
