"""Fit the scale-bias filter's combined measurement noise and parameter drift to one log by maximum likelihood.

Only two noise settings are identifiable from one log (:mod:`kalcal.scenarios.scale_bias.likelihood`): the
combined measurement noise sigma_w = sqrt(sigma_eta^2 + theta1^2 sigma_nu^2), fitted as
``filter.reference_noise_std`` with ``filter.sensor_noise_std`` = 0 (the same filter: its R is sigma_w^2),
and the drift ``filter.parameter_drift_std`` (q per sample). theta itself has a diffuse prior: the fit
does not depend on the settings' prior of a and b.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from kalcal.calibration.diagnostics import innovation_diagnostics
from kalcal.errors import KalcalError
from kalcal.fitting.mle import Free, maximize
from kalcal.fitting.result import FitResult, fitted_point, interval_text
from kalcal.scenarios.scale_bias.likelihood import diffuse_loglik
from kalcal.scenarios.scale_bias.settings import ScaleBiasScenario

NOISE, DRIFT = "filter.reference_noise_std", "filter.parameter_drift_std"
FREE_KEYS = (NOISE, DRIFT)
#: where a drift of 0 starts, per sample
DRIFT_FLOOR = 1e-5
#: each search range spans this factor either side of the start
RANGE = 1e3
IDENTIFIABILITY = (
    "only the combined measurement noise sqrt(sigma_eta^2 + theta1^2 sigma_nu^2) and the drift q are "
    "identifiable from one log: reference_noise_std holds the combination and sensor_noise_std is 0"
)


def fit_scale_bias(
    scenario: ScaleBiasScenario,
    time: np.ndarray,
    reference: np.ndarray,
    sensor: np.ndarray,
    *,
    free: Sequence[str] | None = None,
    profile: bool = False,
    confidence: float = 0.95,
    rate: float | None = None,
    max_updates: int | None = None,
    options=None,
) -> FitResult:
    """Maximum-likelihood sigma_w and q of a scale-bias log, with intervals and the fitted filter's diagnostics.

    Parameters
    ----------
    scenario : ScaleBiasScenario
        Its filter settings are the starts (sigma_w from its R, q from ``parameter_drift_std``, or
        :data:`DRIFT_FLOOR` when 0) and what is not free stays as set.
    time : ndarray, shape (K,)
        s (labels only).
    reference, sensor : ndarray, shape (K,)
        Signal unit; NaN marks a missing value.
    free : sequence of str, optional
        Of :data:`FREE_KEYS` (default both).
    profile, confidence
        As :func:`kalcal.fitting.mle.maximize`.
    rate : float, optional
        The log's sample rate, Hz, for filter.toml's [scenario] (default ``scenario.rate``).
    max_updates : int, optional
        The most samples filter.toml's [scenario] duration may hold (verify's limit per realization).
    options : FitOptions, optional
        Its ``bootstrap`` (B), ``seed``, ``threads`` and ``client``: the parametric bootstrap
        (:mod:`kalcal.fitting.bootstrap`) over logs drawn by :func:`draw_log`.
    """
    free = list(FREE_KEYS if free is None else free)
    unknown = [key for key in free if key not in FREE_KEYS]
    if unknown or not free:
        raise KalcalError(f"--free: expected keys of {', '.join(FREE_KEYS)} for scale-bias, got {','.join(free) or 'none'}")
    unit = scenario.scenario.unit
    noise0 = float(np.sqrt(scenario.filter_noise_variance()))
    drift0 = float(scenario.filter_settings.parameter_drift_std)
    starts = {NOISE: noise0, DRIFT: drift0 if drift0 > 0 else DRIFT_FLOOR}
    units = {NOISE: unit, DRIFT: f"1 and {unit} per sample"}
    parameters = [Free(key, starts[key], starts[key] / RANGE, starts[key] * RANGE, units[key]) for key in free]
    fixed = {NOISE: noise0, DRIFT: drift0}

    def loglik(values):
        merged = {**fixed, **values}
        return diffuse_loglik(reference, sensor, merged[NOISE], merged[DRIFT])[0]

    fit = maximize(loglik, parameters, profile=profile, confidence=confidence)
    chosen = {**fixed, **fitted_point(fit)}
    _, samples, normalized = diffuse_loglik(reference, sensor, chosen[NOISE], chosen[DRIFT])
    diagnostics = innovation_diagnostics(normalized[np.isfinite(normalized)][:, None], ("reference",))
    adequate = diagnostics.consistent
    adequacy = diagnostics.verdict if adequate else (
        f"{diagnostics.verdict}. Even the best settings leave the innovations inconsistent: the model lacks "
        "something, e.g. time-correlated reference noise, a nonlinear sensor response, or drift that is not a random walk"
    )
    counted = _samples(scenario, rate, max_updates)
    from kalcal.fitting.bootstrap import bootstrap_fit

    def draw(rng):
        simulated = draw_log(rng, reference, sensor, chosen[NOISE], chosen[DRIFT])
        # a setting not refitted (unidentified) stays where the log was drawn from
        return lambda values: diffuse_loglik(simulated, sensor, *(({**chosen, **values})[key] for key in (NOISE, DRIFT)))[0]

    boot = bootstrap_fit(options, draw, parameters, fit, confidence)
    notes = [IDENTIFIABILITY, "theta has a diffuse prior: the likelihood is the conditional one, after the first samples that determine theta"]
    return FitResult.from_search(
        scenario.NAME,
        fit,
        fixes=samples,
        nobs_name="samples",
        adequate=adequate,
        adequacy=adequacy,
        diagnostics=diagnostics.as_dict(),
        notes=notes,
        settings=_settings(scenario, chosen, counted),
        comments=_comments(fit, scenario, counted),
        confidence=confidence,
        bootstrap=boot,
    )


def draw_log(rng: np.random.Generator, reference: np.ndarray, sensor: np.ndarray, noise_std: float,
             drift_std: float) -> np.ndarray:
    """A reference column drawn from the scale-bias model at (sigma_w, q) over the log's own sensor column
    (the regressor, kept) and missing pattern (NaN where ``reference`` is NaN), shape (K,):

        theta_k = theta_{k-1} + q eps_k (eps_k ~ N(0, I_2)),   reference_k = theta1_k sensor_k + theta2_k + sigma_w e_k.

    theta_0 is the least-squares line of the log (reference on sensor): the diffuse likelihood does not depend
    on it (any theta_0 gives the same innovations after the diffuse start), it only keeps the simulated column
    on the log's scale. Draws in a fixed order whatever the missing pattern: (K, 2) drift steps, then (K,) noise.
    """
    both = np.isfinite(reference) & np.isfinite(sensor)
    design = np.column_stack([sensor[both], np.ones(int(both.sum()))])
    theta0 = np.linalg.lstsq(design, reference[both], rcond=None)[0]
    steps = rng.standard_normal((reference.size, 2)) * drift_std
    steps[0] = 0.0  # theta_0 itself at the first sample
    theta = theta0 + np.cumsum(steps, axis=0)
    noise = rng.standard_normal(reference.size) * noise_std
    simulated = theta[:, 0] * np.nan_to_num(sensor) + theta[:, 1] + noise
    simulated[~np.isfinite(reference)] = np.nan
    return simulated


def _samples(scenario: ScaleBiasScenario, rate: float | None, max_updates: int | None) -> tuple[float, int, int]:
    """(the log's rate, Hz; the scenario's duration in whole samples at it; those held to ``max_updates``)."""
    rate = float(f"{(rate or scenario.scenario.rate):.6g}")
    samples = max(1, round(scenario.scenario.duration * rate))
    return rate, samples, samples if max_updates is None else min(samples, max_updates)


def _settings(scenario: ScaleBiasScenario, chosen: dict[str, float], counted: tuple[float, int, int]) -> dict[str, dict]:
    """filter.toml's sections: the log's rate, the fitted noise in [filter] and [truth] (drift a random
    walk when q > 0), over the scenario's duration made a whole number of samples, at most
    ``max_updates`` (the most a verification's realization holds): ``counted`` is :func:`_samples`'s."""
    rate, _, samples = counted
    noise, drift = (float(f"{chosen[key]:.6g}") for key in (NOISE, DRIFT))
    section = {"reference_noise_std": noise, "sensor_noise_std": 0.0, "parameter_drift_std": drift}
    return {
        "scenario": {"rate": rate, "duration": samples / rate, "drift": "random-walk" if drift > 0 else "none", "unit": scenario.scenario.unit},
        "filter": dict(section),
        "truth": dict(section),
    }


def _comments(fit, scenario: ScaleBiasScenario, counted: tuple[float, int, int]) -> dict[str, str]:
    """A comment per fitted key for filter.toml: the interval, or why the input is kept; and one on a
    duration shortened to ``max_updates`` samples (``counted``: :func:`_samples`'s)."""
    comments = {}
    rate, samples, kept = counted
    if kept < samples:
        comments["scenario.duration"] = (
            f"duration: the scenario's {scenario.scenario.duration:g} s shortened to {kept / rate:g} s, the {kept} "
            f"samples at {rate:g} Hz that kalcal verify allows a realization (its per-update arrays must fit in memory)"
        )
    for key, p in fit.parameters.items():
        short = key.partition(".")[2]
        if not p.identified:
            comments[short] = f"{short}: {p.note}"
        else:
            comments[short] = f"{short}: fitted, {interval_text(p)}"
    return comments
