"""Calibrate an accelerometer's bias from logged accelerometer samples and GPS fixes.

The accelerometer is integrated open loop into a nominal p_c, v_c (the scenario's scheme); at each fix
the filter updates the error state dx = [p - p_c, v - v_c, b] with dz = [gps_position - p_c,
gps_velocity - v_c]; between fixes it propagates with the report's model over the samples in between.
Estimates: p = p_c + dp, v = v_c + dv, b.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from kalcal.errors import DataError
from kalcal.filters.kalman import UpdateForm, interval_transition, predict, update
from kalcal.filters.mechanization import integrate
from kalcal.models.accel_gps import AccelGpsScenario


@dataclass(frozen=True)
class AccelGpsCalibration:
    """The filter's estimates at each of K fixes used."""

    time: np.ndarray  #: fix times, s, (K,)
    position: np.ndarray  #: p_c + dp, m, (K,)
    velocity: np.ndarray  #: v_c + dv, m/s, (K,)
    bias: np.ndarray  #: b, m/s^2, (K,)
    error_state: np.ndarray  #: posterior [dp, dv, b], (K, 3)
    covariance: np.ndarray  #: posterior P of [dp, dv, b], (K, 3, 3)
    residual: np.ndarray  #: innovations r_k, [m, m/s], (K, 2)
    innovation_cov: np.ndarray  #: S_k, (K, 2, 2)

    @property
    def std(self) -> np.ndarray:
        """1-sigma of [dp, dv, b] from P, (K, 3)."""
        return np.sqrt(np.diagonal(self.covariance, axis1=1, axis2=2))


def _time_tolerance(times: np.ndarray, period: float) -> float:
    """Timing slack, s: a millionth of a sample, or the rounding of the time stamps if that is coarser."""
    return max(1e-6 * period, 8.0 * float(np.spacing(np.max(np.abs(times)))))


def _regular_period(imu_time: np.ndarray, source: str) -> float:
    steps = np.diff(imu_time)
    period = float(np.median(steps))
    worst = int(np.argmax(np.abs(steps - period)))
    if abs(steps[worst] - period) > _time_tolerance(imu_time, period):
        raise DataError(
            f"{source}: accelerometer samples must be evenly spaced; step {worst + 1} is "
            f"{steps[worst]:.9g} s against {period:.9g} s elsewhere"
        )
    return period


def calibrate_accel_gps(
    scenario: AccelGpsScenario,
    imu_time: np.ndarray,
    accel: np.ndarray,
    gps_time: np.ndarray,
    gps_position: np.ndarray,
    gps_velocity: np.ndarray,
    *,
    form: UpdateForm = "joseph",
    source: str = "gps",
    imu_source: str = "imu",
) -> AccelGpsCalibration:
    """Run the report's filter over one log.

    Parameters
    ----------
    scenario : AccelGpsScenario
        Its ``filter`` settings give the noise and the prior; ``scenario.integration`` the scheme.
    imu_time : ndarray, shape (J + 1,)
        Accelerometer sample times, s, strictly increasing and evenly spaced.
    accel : ndarray, shape (J + 1,)
        Measured specific force, m/s^2.
    gps_time, gps_position, gps_velocity : ndarray, shape (K,)
        Fix times (s, on accelerometer sample times), positions (m) and velocities (m/s).
    form : {"joseph", "standard"}
    source, imu_source : str
        Names of the GPS and accelerometer logs, quoted in errors.
    """
    period = _regular_period(imu_time, imu_source)
    tolerance = _time_tolerance(imu_time, period)
    outside = (gps_time < imu_time[0] - tolerance) | (gps_time > imu_time[-1] + tolerance)
    if np.any(outside):
        row = int(np.argmax(outside))
        raise DataError(
            f"{source}: row {row + 1}: fix time {gps_time[row]:.9g} s lies outside the accelerometer log "
            f"[{imu_time[0]:.9g}, {imu_time[-1]:.9g}] s"
        )
    index = np.clip(np.rint((gps_time - imu_time[0]) / period).astype(np.int64), 0, imu_time.size - 1)
    off_tick = np.abs(imu_time[index] - gps_time) > tolerance
    if np.any(off_tick):
        row = int(np.argmax(off_tick))
        raise DataError(f"{source}: row {row + 1}: fix time {gps_time[row]:.9g} s is not on an accelerometer sample")
    backwards = np.flatnonzero(np.diff(index) <= 0)
    if backwards.size:
        row = int(backwards[0]) + 1
        raise DataError(
            f"{source}: row {row + 1}: fix time {gps_time[row]:.9g} s does not come after the previous fix "
            f"({gps_time[row - 1]:.9g} s)"
        )
    p_c, v_c = integrate(accel, period, *scenario.nominal_start(), scenario.scenario.integration)
    model = scenario.filter_model()

    @lru_cache(maxsize=None)
    def transition(steps: int) -> tuple[np.ndarray, np.ndarray]:
        return interval_transition(model.phi, model.gamma, model.w, steps)

    n_fixes = gps_time.size
    states = np.empty((n_fixes, 3))
    covariances = np.empty((n_fixes, 3, 3))
    residuals = np.empty((n_fixes, 2))
    innovations = np.empty((n_fixes, 2, 2))
    x, cov, at = model.x0, model.m0, 0
    for k in range(n_fixes):
        x, cov = predict(x, cov, *transition(int(index[k] - at)))
        at = int(index[k])
        dz = np.array([gps_position[k] - p_c[at], gps_velocity[k] - v_c[at]])
        result = update(x, cov, dz, model.h, model.v, form)
        x, cov = result.x, result.cov
        states[k], covariances[k], residuals[k], innovations[k] = x, cov, result.residual, result.innovation_cov
    return AccelGpsCalibration(
        time=np.asarray(gps_time, dtype=float),
        position=p_c[index] + states[:, 0],
        velocity=v_c[index] + states[:, 1],
        bias=states[:, 2].copy(),
        error_state=states,
        covariance=covariances,
        residual=residuals,
        innovation_cov=innovations,
    )
