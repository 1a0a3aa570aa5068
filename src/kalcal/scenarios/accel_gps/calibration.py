"""Calibrate an accelerometer's bias from logged accelerometer samples and GPS fixes.

The accelerometer is integrated open loop into a nominal p_c, v_c (the scenario's scheme, each sample
with its own interval); at each fix the filter updates the error state dx = [p - p_c, v - v_c, b] with
dz = [gps_position - p_c, gps_velocity - v_c]; between fixes it propagates with the report's model.
Estimates: p = p_c + dp, v = v_c + dv, b.

Real logs, as they are:

* **Fixes between samples.** The nominal is carried to the exact fix time by a partial step
  (:func:`~kalcal.scenarios.accel_gps.mechanization.partial_step`) and the covariance with it.
* **Irregular or dropped samples.** Each step uses its own dt; its noise enters through Gamma(dt), so the
  process noise scales with the step. A step longer than ``max_imu_gap`` sample periods is a gap: it is
  reported, and the run stops if asked to.
* **GPS outages** are simply long intervals: the covariance grows as the model says.
* **Fixes with a NaN** field are skipped and counted; fixes outside the accelerometer log likewise.
* **Per-fix accuracy** (``position_std``, ``velocity_std``) replaces the filter's GPS noise for that fix;
  a NaN there means the filter's setting, and the fixes that took it are counted and flagged.
* **Implausible logs** are refused before any filtering (:mod:`kalcal.calibration.plausibility`): a rate
  outside its sensor's range, a value beyond its physical limit, velocity fixes in another unit than
  the positions' finite differences; a gross velocity/position disagreement of no known unit is flagged.

Between two fixes the filter propagates with the model of the Monte Carlo, piece by piece
(:mod:`kalcal.scenarios.accel_gps.interval_model`): this is exactly the filter that ``verify`` runs on an evenly
spaced log with a fix on every ``steps_per_update``-th sample; the logs are checked first
(:mod:`kalcal.scenarios.accel_gps.log_checks`).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from kalcal.scenarios.accel_gps.evaluation import DIFFUSE_BIAS_STD
from kalcal.scenarios.accel_gps.log import INITS, AccelGpsLog, Init, Prior, prepare_accel_gps_log
from kalcal.scenarios.accel_gps.result import AccelGpsCalibration, ImuGap
from kalcal.calibration.plausibility import CalibrationWarning
from kalcal.core.steps import UpdateForm
from kalcal.scenarios.accel_gps.settings import AccelGpsScenario

__all__ = ["INITS", "AccelGpsCalibration", "AccelGpsLog", "ImuGap", "calibrate_accel_gps", "prepare_accel_gps_log", "prior_conflict"]

#: how far (in the prior's sigmas of the estimate) the bias may lie from its prior mean before the data
#: and the prior are said to conflict: two-sided at 0.999
CONFLICT_CONFIDENCE = 0.999


def calibrate_accel_gps(
    scenario: AccelGpsScenario,
    imu_time: np.ndarray,
    accel: np.ndarray,
    gps_time: np.ndarray,
    gps_position: np.ndarray,
    gps_velocity: np.ndarray,
    *,
    position_std: np.ndarray | None = None,
    velocity_std: np.ndarray | None = None,
    init: Init = "prior",
    max_imu_gap: float = 5.0,
    stop_on_gap: bool = False,
    form: UpdateForm = "joseph",
    gate: float | None = None,
    prior: Prior = "scenario",
    source: str = "gps",
    imu_source: str = "imu",
    imu_rate: float | None = None,
    gps_rate: float | None = None,
    columns: Mapping[str, str] | None = None,
) -> AccelGpsCalibration:
    """Run the report's filter over one log: :func:`prepare_accel_gps_log`, then
    :meth:`AccelGpsLog.calibrate` with the scenario's settings.

    Parameters
    ----------
    scenario : AccelGpsScenario
        Its ``filter`` settings give the noise and the prior; ``scenario.integration`` the scheme.
    imu_time : ndarray, shape (J + 1,)
        Accelerometer sample times, s, strictly increasing.
    accel : ndarray, shape (J + 1,)
        Measured specific force, m/s^2, finite.
    gps_time, gps_position, gps_velocity : ndarray, shape (F,)
        Fix times (s, strictly increasing), positions (m) and velocities (m/s); NaN marks a bad field.
    position_std, velocity_std : ndarray, shape (F,), optional
        Each fix's own 1-sigma (m, m/s); NaN or absent means the filter's setting.
    init : {"prior", "first-fix"}
        Start the nominal at the first accelerometer sample with the scenario's prior (the report), or
        at the first usable fix with its position and velocity and the GPS noise as their covariance.
    max_imu_gap : float
        A step longer than this many median sample periods is reported as a gap.
    stop_on_gap : bool
        Raise DataError at the first gap instead of going on.
    form : {"joseph", "standard", "sqrt"}
        The update form: Joseph (the default, compiled), standard or square-root (numpy loops).
    gate : float, optional
        The innovation gate's confidence (e.g. 0.999): a fix whose NIS under its prior exceeds
        chi2.ppf(gate, 2) is rejected, a prediction only, and listed in ``rejected_rows``. None: no gate.
    prior : {"scenario", "diffuse", "auto"}
        The bias's prior: the settings' (the default), diffuse, or diffuse unless ``filter.bias_std`` was
        given (what a log's calibration uses); :mod:`kalcal.scenarios.accel_gps.log`.
    source, imu_source : str
        Names of the GPS and accelerometer logs, quoted in errors.
    imu_rate, gps_rate : float, optional
        Rates the user stated (Hz, ``scenario.imu_rate`` / ``gps_rate``): the logs' median rates must lie
        within a factor 2 of them. Whether or not given, each rate must be plausible for its sensor
        (:mod:`kalcal.calibration.plausibility`).
    columns : mapping, optional
        ``{role: column name in its file}`` for the roles time (of the GPS log), imu_time, accel,
        position, velocity, position_std, velocity_std, quoted in errors (default: the role's name).

    Raises
    ------
    DataError
        For a log that cannot be used or is implausible, naming the log, the row or rate, and the value.
    """
    log = prepare_accel_gps_log(
        scenario, imu_time, accel, gps_time, gps_position, gps_velocity, position_std=position_std,
        velocity_std=velocity_std, init=init, max_imu_gap=max_imu_gap, stop_on_gap=stop_on_gap, form=form,
        prior=prior, source=source, imu_source=imu_source, imu_rate=imu_rate, gps_rate=gps_rate, columns=columns,
    )  # fmt: skip
    return log.calibrate(gate=gate)


def bias_walk_variance(scenario: AccelGpsScenario, result: AccelGpsCalibration, imu_time: np.ndarray) -> float:
    """The variance a random-walk bias accumulates from the calibration's start to its last fix, m^2/s^4:
    bias_walk_std^2 per accelerometer sample over the span, in median sample periods (0 for a constant or
    a Gauss-Markov bias, whose prior is its stationary spread at any time)."""
    period = float(np.median(np.diff(np.asarray(imu_time, dtype=float))))
    settings = scenario.at_rate(1.0 / period).filter_settings  # per sample at the log's rate, as calibrated
    if settings.bias_correlation_time > 0 or settings.bias_walk_std == 0:
        return 0.0
    return float(settings.bias_walk_std**2 * (result.time[-1] - result.start_time) / period)


def prior_conflict(
    result: AccelGpsCalibration, confidence: float = CONFLICT_CONFIDENCE, *, walk_variance: float = 0.0
) -> CalibrationWarning | None:
    """A warning when the last bias estimate lies too far from its prior mean 0 for the prior to hold.

    Under the model the estimate b_hat = E[b_K | data] has mean 0 and variance Var(b_K) - P_bb (the
    bias's variance at the last fix with no data, less the posterior's), so z = b_hat / sqrt(Var(b_K) -
    P_bb) is N(0, 1): beyond the two-sided ``confidence`` quantile the data and the prior conflict.
    Var(b_K) = sigma_0^2 + ``walk_variance`` (m^2/s^4: a random walk's variance accumulated from the start
    to the last fix, :func:`bias_walk_variance`; a Gauss-Markov bias stays at its stationary sigma_0^2).
    None for a diffuse prior (nothing to conflict with) or when the data did not move the bias's variance.
    """
    from kalcal.stats.distributions import normal_ppf  # loaded on first use, as scipy.special was

    if result.bias_prior_std >= DIFFUSE_BIAS_STD:
        return None
    unconditional = result.bias_prior_std**2 + walk_variance
    spread = unconditional - result.covariance[-1, 2, 2]
    if not spread > 1e-12 * unconditional:
        return None
    z = float(result.bias[-1] / np.sqrt(spread))
    limit = float(normal_ppf(0.5 + confidence / 2))
    if abs(z) <= limit:
        return None
    return CalibrationWarning(
        "prior-conflict",
        f"the bias estimate {result.bias[-1]:.6g} m/s^2 lies {abs(z):.3g} sigma from its prior mean 0 "
        f"(prior 1-sigma {result.bias_prior_std:.3g} m/s^2; beyond {limit:.3g} at {confidence:g}): the prior "
        "does not suit this log; give filter.bias_std a value that does, or leave it unset for a diffuse prior",
    )
