"""The slope regions of an Allan curve, and the value of a line of known slope read off one of them.

Each point of the curve (:mod:`kalcal.calibration.allan`) carries its equivalent degrees of freedom edf_i.
In logs, ln sigma_i has the standard deviation s_i = 1 / sqrt(2 edf_i); a shape tolerance
``SHAPE_TOLERANCE`` is added in quadrature, u_i = sqrt(s_i^2 + delta^2), because a real curve is never
exactly a power law. A contiguous run of points is a region of slope mu when the line of slope mu fitted
to it (weights 1 / u_i^2) passes within ``REGION_Z`` u_i of every point *and* the lines of the other two
slopes do not: a run the data cannot tell apart from another slope is no region. The longest run of slope
-1/2 is the white region; the flat and +1/2 runs are the longest from its end on (flicker and random walk
show at longer taus; a low-pass filter's flat start or a vibration's bump at short taus is neither).

A line's value (:func:`read_line`) is the weighted mean over its region, in logs, of each point moved
along the slope to the tau it is read at, with the other noises' Allan variance taken off first.
"""

from __future__ import annotations

import numpy as np

from kalcal.calibration.allan import AllanCurve

#: threshold, in combined log-standard deviations, of every region and minimum test
REGION_Z = 3.0
#: tolerance (in ln sigma, about 2%) for a real curve that is not exactly a power law
SHAPE_TOLERANCE = 0.02
#: the log-log slopes of the three regions
SLOPES = {"white": -0.5, "flat": 0.0, "rate_random_walk": 0.5}


def _fits(y: np.ndarray, x: np.ndarray, u: np.ndarray, slope: float) -> bool:
    """Whether the line of ``slope`` fitted to (x, y) in logs passes within REGION_Z u of every point."""
    weights = 1.0 / u**2
    residual = y - slope * x
    intercept = np.sum(weights * residual) / np.sum(weights)
    return bool(np.all(np.abs(residual - intercept) <= REGION_Z * u))


def slope_regions(curve: AllanCurve) -> dict[str, tuple[int, int] | None]:
    """The longest run (first, last index) of each slope in ``SLOPES`` that fits it and no other slope.

    The white-noise run is found first; the flat and +1/2 runs are looked for from its last point on,
    since flicker and random walk show at longer taus than white noise (a low-pass filter's flat start
    or a vibration's rise at short taus is neither).
    """
    valid = curve.adev > 0
    y = np.log(np.where(valid, curve.adev, 1.0))
    x = np.log(curve.tau)
    u = np.hypot(curve.log_std, SHAPE_TOLERANCE)
    regions: dict[str, tuple[int, int] | None] = {}
    for name, slope in SLOPES.items():
        start = 0 if name == "white" or regions["white"] is None else regions["white"][1]
        best: tuple[int, int] | None = None
        best_key = (0, 0.0)
        for first in range(start, len(x)):
            for last in range(first + 1, len(x)):
                run = slice(first, last + 1)
                if not np.all(valid[run]):
                    break
                if not _fits(y[run], x[run], u[run], slope):
                    continue
                if any(_fits(y[run], x[run], u[run], other) for key, other in SLOPES.items() if key != name):
                    continue
                key = (last - first + 1, float(np.sum(1.0 / u[run] ** 2)))
                if key > best_key:
                    best, best_key = (first, last), key
        regions[name] = best
    return regions


def read_line(
    curve: AllanCurve, region: tuple[int, int], slope: float, at: float, subtract: np.ndarray | None = None
) -> tuple[float, float, float] | None:
    """(value, low, high) of the line of ``slope`` through ``region``, read at tau = ``at`` s.

    Each point gives c_i = sigma_i (at / tau_i)^slope, after ``subtract`` (the other noises' Allan variance,
    (T,) or a scalar, (m/s^2)^2) is taken from sigma_i^2 and from its bounds; the value is the weighted mean of ln c_i
    (weights 1 / u_i^2) and the bounds the same mean of the points' log bounds. Points whose lower bound
    the subtraction would make nonpositive are left out; None if none is left.
    """
    index = np.arange(region[0], region[1] + 1)
    extra = np.zeros(index.size) if subtract is None else np.broadcast_to(subtract, curve.tau.shape)[index]
    sigma2, low2, high2 = (curve.adev[index] ** 2 - extra, curve.low[index] ** 2 - extra, curve.high[index] ** 2 - extra)
    keep = low2 > 0
    if not np.any(keep):
        return None
    scale = (at / curve.tau[index][keep]) ** slope
    weights = 1.0 / np.hypot(curve.log_std[index][keep], SHAPE_TOLERANCE) ** 2
    weights = weights / np.sum(weights)

    def mean_log(values2: np.ndarray) -> float:
        return float(np.exp(np.sum(weights * np.log(np.sqrt(values2[keep]) * scale))))

    return mean_log(sigma2), mean_log(low2), mean_log(high2)
