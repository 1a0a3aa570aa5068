"""Smoothed estimates of a calibration run: every fix's state given the whole log (RTS smoother).

The filter's estimate at fix k uses the fixes up to k; the smoothed one uses all of them, so early
position, velocity and bias estimates gain most (the last fix's are the filter's). The error state
[dp, dv, b] is smoothed by :func:`kalcal.core.smoother.rts_smooth` over the filter's priors,
posteriors and transitions, and added to the same nominal as the filter's: p_s = p_c + dp_s,
v_s = v_c + dv_s, b_s. With a scale-factor state the filter runs on [dp, dv, b', s']; the smoother runs
there too, and its result is converted to [dp, dv, b, s] as the filter's own estimates are.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kalcal.scenarios.accel_gps.result import AccelGpsCalibration
from kalcal.scenarios.accel_gps.interval_model import scale_parameters
from kalcal.core.smoother import rts_smooth
from kalcal.errors import DataError


@dataclass(frozen=True)
class SmoothedCalibration:
    """The smoothed estimates at each of the K fixes of a calibration run."""

    time: np.ndarray  #: fix times, s, (K,)
    position: np.ndarray  #: p_c + dp_s, m, (K,)
    velocity: np.ndarray  #: v_c + dv_s, m/s, (K,)
    bias: np.ndarray  #: b_s, m/s^2, (K,)
    error_state: np.ndarray  #: smoothed [dp, dv, b] (and s with a scale factor), (K, d)
    covariance: np.ndarray  #: its covariance, (K, d, d)

    @property
    def scale(self) -> np.ndarray:
        """s_s, the smoothed scale-factor error (dimensionless), (K,); only with a scale-factor state."""
        if self.error_state.shape[1] < 4:
            raise AttributeError("this calibration estimates no scale factor")
        return self.error_state[:, 3]

    @property
    def std(self) -> np.ndarray:
        """1-sigma of the smoothed error state, (K, d)."""
        return np.sqrt(np.clip(np.diagonal(self.covariance, axis1=1, axis2=2), 0.0, None))


def smooth_calibration(result: AccelGpsCalibration) -> SmoothedCalibration:
    """RTS-smooth a calibration run.

    Parameters
    ----------
    result : AccelGpsCalibration
        From :func:`~kalcal.scenarios.accel_gps.calibration.calibrate_accel_gps`, which keeps the priors M_k and the
        transitions Phi_k the smoother needs.

    Raises
    ------
    DataError
        The run does not carry its priors and transitions.
    """
    needed = (
        result.filter_state, result.filter_covariance, result.prior_state, result.prior_covariance, result.transitions
    )
    if any(array is None for array in needed):
        raise DataError("smoothing needs the filter's priors and transitions, which this calibration run does not hold")
    smoothed = rts_smooth(*needed)
    state, covariance = smoothed.state, smoothed.cov
    if state.shape[1] == 4:  # the filter's [dp, dv, b', s'] -> [dp, dv, b, s]
        state, covariance = scale_parameters(state, covariance)
    nominal_p = result.position - result.error_state[:, 0]
    nominal_v = result.velocity - result.error_state[:, 1]
    return SmoothedCalibration(
        time=result.time,
        position=nominal_p + state[:, 0],
        velocity=nominal_v + state[:, 1],
        bias=state[:, 2].copy(),
        error_state=state,
        covariance=covariance,
    )
