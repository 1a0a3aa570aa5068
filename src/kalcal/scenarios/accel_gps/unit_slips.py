"""accel-gps's unit slips that still give a number: acceleration in g or with gravity left in, GPS in mm or ft.

The slips named: an accelerometer in g or with gravity left in, positions in mm or ft, and a GPS log
wholly in mm or ft.

The checks of :mod:`kalcal.calibration.plausibility` let these through: each value is within its physical
limit and the velocity fixes agree with the positions. Two fits over the usable fixes name them, as the
velocity check (:func:`~kalcal.scenarios.accel_gps.log_checks.velocity_consistency`) names km/h: an error
naming the likely unit, or, for gravity, a :class:`~kalcal.calibration.plausibility.CalibrationWarning`.
"""

from __future__ import annotations

import numpy as np

from kalcal.calibration.plausibility import MIN_RATE_SAMPLES, CalibrationWarning
from kalcal.errors import DataError


#: standard gravity, m/s^2
STANDARD_GRAVITY = 9.80665
#: accelerometer units whose factor to m/s^2 a fitted ratio is tested against: a [m/s^2] = factor * a [unit]
ACCEL_UNITS = (("g", STANDARD_GRAVITY),)
#: position units whose factor a fitted ratio is tested against: p [unit] = factor * p [m]
POSITION_UNITS = (("millimetres", 1000.0), ("feet", 1 / 0.3048))
#: units of a GPS log wholly in another unit (position and velocity both), by the factor the fitted ratio of
#: the accelerometer fit is tested against: v [unit/s] = factor * v [m/s], so the GPS velocity changes are
#: that many times the integrated accelerometer (the position fit, velocity against position, sees 1)
GPS_UNITS = (("millimetres (and mm/s)", 1000.0), ("feet (and ft/s)", 1 / 0.3048))
#: a fitted ratio within this relative distance of a unit's factor names that unit: wider than
#: :data:`~kalcal.scenarios.accel_gps.log_checks.UNIT_TOLERANCE`, for an integral of noisy samples is fitted, not a difference of fixes
SLIP_TOLERANCE = 0.05
#: ... and only when it lies this many standard errors from 1 (what SI units give) and from 0 (what a log
#: without motion gives): the fits' residuals are not white (the bias drifts, the integrals carry the
#: noise along), so their standard errors are optimistic and the margin is wide
SLIP_Z = 10.0
#: a bias within this relative distance of g is gravity left in: g is within about 0.27 % of standard
#: gravity over the Earth (9.780 m/s^2 at the equator, 9.832 at the poles), a mount tilted by 25 degrees
#: reads 0.91 g, a MEMS bias is at most a few hundredths of g
GRAVITY_BAND = 0.1


def _cumulative_trapezoid(time: np.ndarray, values: np.ndarray) -> np.ndarray:
    """int_{time[0]}^{time[j]} values dt by the trapezoid rule, shape of ``time``."""
    return np.concatenate([[0.0], np.cumsum(0.5 * (values[1:] + values[:-1]) * np.diff(time))])


def _fit(y: np.ndarray, columns: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray] | None:
    """Least squares of y on ``columns``: (coefficients, their standard errors from the residuals), or
    None for fewer than two degrees of freedom or a singular design. Columns are scaled to unit norm
    first (an integral in m/s next to a column of ones), and the normal equations solved by Cholesky."""
    import scipy.linalg

    design = np.stack(columns, axis=1)
    rows, count = design.shape
    if rows < count + 2:
        return None
    norms = np.linalg.norm(design, axis=0)
    if not np.all(norms > 0):
        return None
    scaled = design / norms
    gram = scaled.T @ scaled
    try:
        factor = scipy.linalg.cho_factor(gram)
    except np.linalg.LinAlgError:
        return None
    coefficients = scipy.linalg.cho_solve(factor, scaled.T @ y)
    residual = y - scaled @ coefficients
    variance = float(residual @ residual) / (rows - count)
    # the diagonal of gram^-1, one column at a time (count is 2 or 3)
    diagonal = np.array([scipy.linalg.cho_solve(factor, e)[i] for i, e in enumerate(np.eye(count))])
    return coefficients / norms, np.sqrt(variance * np.maximum(diagonal, 0.0)) / norms


def _named_slip(ratio: float, se: float, factor: float) -> bool:
    """Whether a fitted ``ratio`` (standard error ``se``) is the unit of ``factor``: within
    :data:`SLIP_TOLERANCE` of it, and measurably different (:data:`SLIP_Z` standard errors) both from SI's
    1 and from 0. The last keeps a log without motion out: its slope is 0 give or take a wide se (0.045 on
    a 60 s motionless log), and without it landed within 5% of 1/g in 3 of 300 seeds, refused as "converted
    from g to m/s^2 twice"."""
    return abs(ratio / factor - 1) <= SLIP_TOLERANCE and abs(ratio - 1) > SLIP_Z * se and abs(ratio) > SLIP_Z * se


def accelerometer_units(
    imu_time: np.ndarray,
    accel: np.ndarray,
    fix_time: np.ndarray,
    velocity: np.ndarray,
    imu_source: str,
    column: str = "accel",
    gps_source: str = "the GPS log",
) -> CalibrationWarning | None:
    """The accelerometer against the GPS velocities: its unit, and gravity left in.

    With I(t) the accelerometer integrated by the trapezoid rule (at the fix times, interpolated), the
    velocity fixes are fitted as v_f = k I(t_f) + v_0 - b t_f: a measured a [unit] = (a [m/s^2] + b) / k
    gives k = 1 for m/s^2 and k = g = 9.807 for an accelerometer in g (the integrated accelerometer is
    then 1/9.81 of the GPS velocity change), and k = 3.281 or 1000 for a GPS log wholly in feet or millimetres
    (position and velocity both: the position fit of :func:`position_units` then sees 1). A k within
    :data:`SLIP_TOLERANCE` of an accelerometer unit's factor (:data:`ACCEL_UNITS`), or of its inverse
    (converted twice), or of a GPS unit's factor (:data:`GPS_UNITS`), and :data:`SLIP_Z` standard errors
    from both 1 and 0 is an error naming the unit. Otherwise, b is fitted with k = 1 (v_f - I(t_f) = v_0 - b t_f, which a log
    without motion still determines): a b within :data:`GRAVITY_BAND` of +-g and :data:`SLIP_Z` standard
    errors from 0 is gravity left in the vertical accelerometer, flagged (the calibrated bias then holds
    gravity; it is a number, not the sensor's bias).

    Parameters
    ----------
    imu_time, accel : ndarray, shape (J,)
        Sample times (s, increasing) and accelerometer values (its unit, m/s^2 expected).
    fix_time, velocity : ndarray, shape (F,)
        The usable fixes: times within [imu_time[0], imu_time[-1]] (s) and velocities (m/s).
    imu_source, column : str
        The accelerometer log and its column, quoted.
    gps_source : str
        The GPS log, quoted when its units are named.

    Returns
    -------
    CalibrationWarning or None
        ``gravity-in-accel`` when the bias is near +-g.

    Raises
    ------
    DataError
        When k names a unit (of the accelerometer, or of the GPS log).
    """
    imu_time, accel = np.asarray(imu_time, dtype=float), np.asarray(accel, dtype=float)
    fix_time, velocity = np.asarray(fix_time, dtype=float), np.asarray(velocity, dtype=float)
    if imu_time.size < MIN_RATE_SAMPLES or fix_time.size < 5:
        return None
    integral = np.interp(fix_time, imu_time, _cumulative_trapezoid(imu_time, accel))
    elapsed = fix_time - fix_time[0]
    fitted = _fit(velocity, [integral, np.ones_like(elapsed), elapsed])
    if fitted is not None:
        (k, _, _), (se, _, _) = fitted
        # only a slope near a unit's factor is quoted, so 1 / k is taken only where k is far from 0
        inverse = f"{1 / k:.4g}" if k != 0 else "inf"
        detail = (
            f"the GPS velocity changes are {k:.4g} times the integrated accelerometer (integrated "
            f"accelerometer / GPS velocity change = {inverse})"
        )
        for unit, factor in ACCEL_UNITS:
            if _named_slip(k, se, factor):
                raise DataError(f"{imu_source}: column {column!r}: {detail}: is the acceleration in {unit} instead of m/s^2?")
            if _named_slip(k, se, 1 / factor):
                raise DataError(
                    f"{imu_source}: column {column!r}: {detail}: the acceleration looks {factor:.4g} times too large "
                    f"(converted from {unit} to m/s^2 twice?)"
                )
        for unit, factor in GPS_UNITS:
            if _named_slip(k, se, factor):
                raise DataError(
                    f"{gps_source}: {detail}: are its position and velocity in {unit} instead of m (and m/s)?"
                )
    fitted = _fit(velocity - integral, [np.ones_like(elapsed), elapsed])
    if fitted is None:
        return None
    (_, slope), (_, se) = fitted
    bias = -slope
    if abs(abs(bias) / STANDARD_GRAVITY - 1) <= GRAVITY_BAND and abs(bias) > SLIP_Z * se:
        return CalibrationWarning(
            "gravity-in-accel",
            f"{imu_source}: column {column!r}: the accelerometer's offset from the GPS velocity changes is "
            f"{bias:.4g} m/s^2, near {'+' if bias > 0 else '-'}g ({STANDARD_GRAVITY:g} m/s^2): was gravity removed "
            "from the vertical accelerometer? (the calibrated bias then holds gravity)",
        )
    return None


def position_units(
    time: np.ndarray, position: np.ndarray, velocity: np.ndarray, source: str, column: str = "position"
) -> None:
    """The positions against the velocities integrated: their unit.

    With V(t) the velocity fixes integrated by the trapezoid rule, the positions are fitted as
    p_f = m V(t_f) + p_0: m = 1 for positions in m, 1000 for millimetres and 3.281 for feet (the
    position differences are that many times the integrated velocity). An m within
    :data:`SLIP_TOLERANCE` of a unit's factor (:data:`POSITION_UNITS`) and :data:`SLIP_Z` standard errors
    from both 1 and 0 is an error naming the unit.

    Parameters
    ----------
    time, position, velocity : ndarray, shape (F,)
        The usable fixes: s, m, m/s.
    source, column : str
        The GPS log and its position column, quoted.

    Raises
    ------
    DataError
        When m names a unit.
    """
    time, position, velocity = (np.asarray(a, dtype=float) for a in (time, position, velocity))
    if time.size < 5:
        return
    fitted = _fit(position, [_cumulative_trapezoid(time, velocity), np.ones_like(time)])
    if fitted is None:
        return
    (m, _), (se, _) = fitted
    for unit, factor in POSITION_UNITS:
        if _named_slip(m, se, factor):
            raise DataError(
                f"{source}: column {column!r}: the position differences are {m:.4g} times the velocity fixes "
                f"integrated ({factor:.4g} for {unit}): is the position in {unit} instead of m?"
            )
