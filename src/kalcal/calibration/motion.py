"""Signs that a log meant to be static is not: a rise faster than any noise's, a steady drift, a step."""

from __future__ import annotations

import numpy as np

from kalcal.calibration.allan import AllanCurve
from kalcal.calibration.plausibility import CalibrationWarning
from kalcal.calibration.slopes import SHAPE_TOLERANCE

#: threshold, in combined log-standard deviations, of the rise faster than +1/2 that marks motion (one-sided,
#: over the ~T^2/2 pairs of points of a curve of T points)
MOTION_Z = 4.0
#: blocks whose means the step test compares, and the fewest samples in a block
STEP_BLOCKS, STEP_BLOCK_MIN = 64, 8
#: a jump between neighbouring block means this many robust standard deviations (1.4826 MAD) is a step
STEP_Z = 8.0
#: a mean jump between block means this many standard errors from 0 is a steady drift (a trend)
TREND_Z = 5.0


def motion_warnings(accel: np.ndarray, curve: AllanCurve, rate: float) -> tuple[CalibrationWarning, ...]:
    """Signs that a log is not static, each a ``not-static`` warning.

    * **Motion or a trend.** No noise's Allan deviation rises faster than the rate random walk's
      +1/2 slope, nor does a sum of them; a sinusoidal motion rises at up to +1 and a linear trend at
      exactly +1. Flagged where some pair of points i < j rises faster than +1/2 by more than
      ``MOTION_Z`` combined log-standard deviations: ln sigma_j - ln sigma_i - (ln tau_j - ln tau_i) / 2 >
      MOTION_Z sqrt(u_i^2 + u_j^2).
    * **A trend and a step.** The log cut into ``STEP_BLOCKS`` blocks (of at least ``STEP_BLOCK_MIN``
      samples, 16 blocks at least, else these two are not looked for): for noise (white, flicker, random
      walk), the jumps between neighbouring block means have mean 0 and are alike (Gaussian). A steady
      drift makes their mean more than ``TREND_Z`` standard errors (std / sqrt(jumps)) from 0; a sensor
      moved or tilted once makes one jump more than ``STEP_Z`` robust standard deviations (1.4826 times
      the median absolute deviation of the jumps) from their median.

    A drift too slow to show in these (below about 5 standard errors of the block means over the log)
    passes: it is then small against the noise the log shows.

    Parameters
    ----------
    accel : (n,) m/s^2, the log's samples.
    curve : its Allan deviation (:func:`allan_curve`).
    rate : Hz.
    """
    found: list[CalibrationWarning] = []
    valid = curve.adev > 0
    y = np.log(np.where(valid, curve.adev, 1.0))
    x = np.log(curve.tau)
    u = np.hypot(curve.log_std, SHAPE_TOLERANCE)
    excess = (y[None, :] - y[:, None]) - 0.5 * (x[None, :] - x[:, None])
    z = excess / np.hypot(u[:, None], u[None, :])
    z = np.where(np.triu(np.ones_like(z, dtype=bool), 1) & valid[:, None] & valid[None, :], z, -np.inf)
    if z.size and np.max(z) > MOTION_Z:
        i, j = np.unravel_index(int(np.argmax(z)), z.shape)
        slope = (y[j] - y[i]) / (x[j] - x[i])
        found.append(
            CalibrationWarning(
                "not-static",
                f"the log does not look static: its Allan deviation rises with slope {slope:.2g} from tau = "
                f"{curve.tau[i]:.3g} s to {curve.tau[j]:.3g} s, faster than any noise (a rate random walk "
                "rises at +1/2): motion, vibration or a trend dominates, and the values read off describe it, "
                "not the sensor's noise",
            )
        )
    blocks = min(STEP_BLOCKS, accel.size // STEP_BLOCK_MIN)
    if blocks >= 16:
        length = accel.size // blocks
        means = accel[: blocks * length].reshape(blocks, length).mean(axis=1)
        jumps = np.diff(means)
        centred = jumps - np.median(jumps)
        spread = 1.4826 * float(np.median(np.abs(centred)))
        t_drift = float(np.mean(jumps) / (np.std(jumps, ddof=1) / np.sqrt(jumps.size))) if np.ptp(jumps) > 0 else 0.0
        if abs(t_drift) > TREND_Z:
            found.append(
                CalibrationWarning(
                    "not-static",
                    f"the log does not look static: its level drifts steadily by {np.mean(jumps) / length * rate:.3g} "
                    f"m/s^2 per s (the mean jump between block means is {abs(t_drift):.3g} standard errors from 0, "
                    f"more than {TREND_Z:g}; noise wanders with no steady drift): a temperature ramp or slow motion?",
                )
            )
        if spread > 0 and np.max(np.abs(centred)) > STEP_Z * spread:
            b = int(np.argmax(np.abs(centred)))
            found.append(
                CalibrationWarning(
                    "not-static",
                    f"the log does not look static: its level steps by {jumps[b]:.3g} m/s^2 between rows "
                    f"{b * length + 1}-{(b + 1) * length} and {(b + 1) * length + 1}-{(b + 2) * length} "
                    f"({np.abs(centred[b]) / spread:.3g} robust standard deviations of such jumps, more than "
                    f"{STEP_Z:g}): the sensor moved or tilted?",
                )
            )
    return tuple(found)
