"""Is a log plausible for the sensor it claims to be? Rates, physical limits and unit slips.

A log with times in milliseconds, a velocity in km/h or one corrupt sample of 1e300 still runs through a
Kalman filter and gives a confident number; these checks refuse such logs (:class:`~kalcal.errors.DataError`,
naming the file, the row or the rate and the likely unit) or flag them (:class:`CalibrationWarning`, a
code and a message that the jobs write into ``summary.json`` ``warnings`` and the CLI prints).

The ranges and limits, chosen wide enough for every sensor kalcal is meant for and narrow enough to
catch the usual unit slips:

==============================  =======================  ==========================================
quantity                        plausible                why
==============================  =======================  ==========================================
accelerometer sample rate       1 Hz .. 100 kHz          the median sample interval; an IMU below
                                                         1 Hz or above 100 kHz is a unit slip
GNSS fix rate                   0.01 Hz .. 100 Hz        one fix per 100 s .. a 100 Hz receiver
accelerometer rate vs GNSS      at least the fix rate    the accelerometer is the fast sensor
a rate the user set             within a factor of 2     ``scenario.imu_rate`` / ``gps_rate``
abs(acceleration)               <= 1e4 m/s^2             about 1000 g, beyond any navigation or
                                                         high-g MEMS accelerometer (a few hundred g)
abs(position), position_std     <= 1e9 m                 beyond the Moon
abs(velocity), velocity_std     <= 1e5 m/s               ten times the escape velocity
abs(time) of the accelerometer  <= 1e11 s                about 3000 years (epoch seconds are 2e9)
==============================  =======================  ==========================================

Rates are median intervals, checked for logs of at least four samples; a bound itself is plausible (to a
relative :data:`RATE_MARGIN`, for the rounding of times such as k / 100). A rate outside its range names
the time unit that would bring it well inside (times in ms, us or ns, or in minutes or hours): only a rate
more than a factor :data:`HINT_BEYOND` beyond its range, and only a unit that puts it more than a factor
:data:`HINT_MARGIN` inside (a unit slip moves a rate by 60 or more; a rate just beyond a bound is not one). The
velocity fixes are compared with the positions' finite differences, see :func:`velocity_consistency`;
a ratio of 1e-3, 1e-6, 1e-9, 60 or 3600 there names times in ms, us, ns, minutes or hours in both logs.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

from kalcal.errors import DataError

#: plausible accelerometer sample rates, Hz (median sample interval)
IMU_RATE_RANGE = (1.0, 1e5)
#: plausible GNSS fix rates, Hz (median fix interval)
GNSS_RATE_RANGE = (0.01, 100.0)
#: a rate within this relative distance of a bound is at the bound (times rounded in the log)
RATE_MARGIN = 1e-6
#: a unit hint needs the rate this factor beyond its range (5 Hz fixes in ms read 0.005 Hz, a factor 2)
HINT_BEYOND = 1.5
#: ... and the unit to put it this factor inside the range
HINT_MARGIN = 2.0
#: fewest samples whose median interval is checked as a rate (three intervals)
MIN_RATE_SAMPLES = 4
#: a rate the user set (scenario.imu_rate / gps_rate) and the log's may differ by at most this factor
RATE_FACTOR = 2.0
#: physical limits of the magnitude of each quantity, in its SI unit
LIMITS = {"accel": 1e4, "position": 1e9, "velocity": 1e5, "time": 1e11}
UNITS = {"accel": "m/s^2", "position": "m", "velocity": "m/s", "time": "s"}
#: times in these units instead of s give a rate this many times too low (first) or too high (last)
TIME_UNITS = (("milliseconds", 1e3), ("microseconds", 1e6), ("nanoseconds", 1e9), ("minutes", 1 / 60), ("hours", 1 / 3600))
#: velocity units whose factor to m/s the fitted ratio is tested against: v [m/s] = factor * v [unit]
VELOCITY_UNITS = (("km/h", 1 / 3.6), ("mph", 0.44704), ("knots", 1852 / 3600))
#: a fitted ratio within this relative distance of a unit's factor names that unit
UNIT_TOLERANCE = 0.02
#: median |z| of velocity minus finite difference above which the fixes disagree grossly (0.67 expected)
VELOCITY_Z = 5.0
#: pairs of fixes farther apart than this many median fix intervals are not compared (an outage)
PAIR_SPAN = 1.5


@dataclass(frozen=True)
class CalibrationWarning:
    """Something a calibration's user must know: a short stable ``code`` and a one-line ``message``."""

    code: str
    message: str

    def as_dict(self) -> dict[str, str]:
        return asdict(self)


def median_rate(time: np.ndarray) -> float:
    """1 / the median interval of strictly increasing ``time`` (s), Hz; NaN for fewer than
    :data:`MIN_RATE_SAMPLES` samples (too few intervals for a median to mean a rate)."""
    time = np.asarray(time, dtype=float)
    return float(1.0 / np.median(np.diff(time))) if time.size >= MIN_RATE_SAMPLES else float("nan")


def _within(rate: float, low: float, high: float) -> bool:
    """``low <= rate <= high`` to a relative :data:`RATE_MARGIN` at either bound."""
    return low * (1 - RATE_MARGIN) <= rate <= high * (1 + RATE_MARGIN)


def _unit_hint(rate: float, low: float, high: float, typical: float, inside: float = HINT_MARGIN) -> str:
    """': are the times in X?' for the time unit that brings ``rate`` well into [low, high] nearest ``typical``;
    empty unless ``rate`` is more than :data:`HINT_BEYOND` beyond the range and a unit puts it into
    [low * inside, high / inside]."""
    if low / HINT_BEYOND <= rate <= high * HINT_BEYOND:
        return ""
    fits = [
        (abs(np.log(rate * factor / typical)), unit)
        for unit, factor in TIME_UNITS
        if low * inside <= rate * factor <= high / inside
    ]
    return f": are the times in {min(fits)[1]}?" if fits else ""


def check_rate(
    time: np.ndarray,
    sensor: str,
    source: str,
    column: str = "time",
    *,
    expected: float | None = None,
    setting: str = "",
) -> float:
    """The log's median sample rate (Hz), refused when implausible for ``sensor``.

    Parameters
    ----------
    time : ndarray, shape (n,)
        Sample times, s, strictly increasing.
    sensor : {"accelerometer", "gnss"}
        Whose range applies: :data:`IMU_RATE_RANGE` or :data:`GNSS_RATE_RANGE`.
    source, column : str
        The log and its time column, quoted in the error.
    expected : float, optional
        A rate the user set (Hz): the log's must lie within a factor :data:`RATE_FACTOR` of it.
    setting : str
        The setting's name (e.g. ``scenario.imu_rate``), quoted in the error.

    Raises
    ------
    DataError
        Naming the rate, the range and the likely unit of the times.
    """
    rate = median_rate(time)
    if not np.isfinite(rate):
        return rate
    low, high = IMU_RATE_RANGE if sensor == "accelerometer" else GNSS_RATE_RANGE
    name = "accelerometer sample rate" if sensor == "accelerometer" else "GPS fix rate"
    typical = 200.0 if sensor == "accelerometer" else 5.0
    if not _within(rate, low, high):
        raise DataError(
            f"{source}: column {column!r}: {name} {rate:.6g} Hz (median step {1 / rate:.6g} s) is implausible "
            f"(expected {low:g} Hz to {high:g} Hz){_unit_hint(rate, low, high, typical)}"
        )
    if expected is not None and not _within(rate, expected / RATE_FACTOR, expected * RATE_FACTOR):
        raise DataError(
            f"{source}: column {column!r}: {name} {rate:.6g} Hz differs from {setting or 'the set rate'} = "
            f"{expected:g} Hz by more than a factor {RATE_FACTOR:g}"
            f"{_unit_hint(rate, expected / RATE_FACTOR, expected * RATE_FACTOR, expected, inside=1.0)}"
        )
    return rate


def check_imu_faster(imu_rate: float, gps_rate: float, imu_source: str) -> None:
    """Refuse an accelerometer that samples less often than the GPS fixes (its times likely in ms)."""
    if np.isfinite(gps_rate) and imu_rate < gps_rate * (1 - RATE_MARGIN):
        low, high = max(IMU_RATE_RANGE[0], gps_rate), IMU_RATE_RANGE[1]
        raise DataError(
            f"{imu_source}: accelerometer sample rate {imu_rate:.6g} Hz is below the GPS fix rate {gps_rate:.6g} Hz "
            f"(the accelerometer is the fast sensor){_unit_hint(imu_rate, low, high, 200.0)}"
        )


def check_limit(
    values: np.ndarray,
    quantity: str,
    source: str = "",
    column: str = "",
    *,
    limit: float | None = None,
    unit: str | None = None,
) -> None:
    """Refuse any value whose magnitude exceeds the physical limit of ``quantity``.

    Parameters
    ----------
    values : ndarray, shape (n,)
        In the SI unit of ``quantity`` (NaN is passed over).
    quantity : {"accel", "position", "velocity", "time"}
        Which of :data:`LIMITS` applies.
    source, column : str
        Quoted in the error with the 1-based data row, where given.
    limit, unit : float, str, optional
        For a quantity not in :data:`LIMITS` (e.g. a scale-bias signal in its own unit).
    """
    limit = LIMITS[quantity] if limit is None else limit
    unit = UNITS[quantity] if unit is None else unit
    values = np.asarray(values, dtype=float)
    with np.errstate(invalid="ignore"):
        beyond = np.abs(values) > limit
    if np.any(beyond):
        row = int(np.argmax(beyond))
        where = (f"{source}: " if source else "") + f"row {row + 1}" + (f", column {column!r}" if column else "")
        raise DataError(
            f"{where}: {float(values[row]):.6g} {unit} is beyond the physical limit of {limit:g} {unit} for "
            f"{quantity} (a corrupt sample, or not in {unit}?)"
        )


def velocity_consistency(
    time: np.ndarray,
    position: np.ndarray,
    velocity: np.ndarray,
    position_std: np.ndarray,
    velocity_std: np.ndarray,
    source: str,
    columns: Sequence[str] = ("position", "velocity"),
) -> CalibrationWarning | None:
    """Compare the velocity fixes with the positions' finite differences, on the scale of the stated noise.

    For consecutive usable fixes i, i + 1 (at most :data:`PAIR_SPAN` median intervals apart),
    d_i = (p_{i+1} - p_i) / dt_i - (v_i + v_{i+1}) / 2, whose standard deviation from the stated noise is
    s_i = sqrt(sigma_p,i^2 + sigma_p,i+1^2) / dt_i (+) sqrt(sigma_v,i^2 + sigma_v,i+1^2) / 2 (+) m_i (in
    quadrature), m_i = |v_{j+1} - 2 v_j + v_{j-1}| / 12 (the larger at j = i, i + 1) for the trapezoid's own
    error, dt^2 jerk / 12, under motion. For consistent fixes
    z_i = d_i / s_i has a median |z| of about 0.67 (less when the position noise is correlated in time).
    When the median |z| exceeds :data:`VELOCITY_Z` the fixes disagree grossly: the ratio
    c = sum(f_i vbar_i) / sum(vbar_i^2) of the finite differences f_i to the mean velocities vbar_i is
    fitted, and a c within :data:`UNIT_TOLERANCE` of a time unit's ratio (1e-3, 1e-6, 1e-9 for times in
    ms, us, ns in both logs; 60, 3600 for minutes, hours) or of a velocity unit's factor (1/3.6 for km/h,
    0.447 for mph, 0.514 for knots, or their inverses) is an error naming the unit; any other gross disagreement is a
    warning (the noise settings far too small, or the two not of the same antenna).

    Parameters
    ----------
    time, position, velocity, position_std, velocity_std : ndarray, shape (F,)
        The usable fixes (finite), s, m, m/s, m, m/s.
    source : str
        The GPS log, quoted in the error or warning.
    columns : (str, str) or (str, str, str)
        The log's position, velocity (and time) columns, quoted.

    Returns
    -------
    CalibrationWarning or None

    Raises
    ------
    DataError
        When the ratio points to a unit (of time or of velocity).
    """
    time, position, velocity = (np.asarray(a, dtype=float) for a in (time, position, velocity))
    if time.size < 4:
        return None
    dt = np.diff(time)
    pairs = dt <= PAIR_SPAN * np.median(dt)
    if np.count_nonzero(pairs) < 3:
        return None
    sp2, sv2 = np.asarray(position_std, dtype=float) ** 2, np.asarray(velocity_std, dtype=float) ** 2
    finite_difference = np.diff(position)[pairs] / dt[pairs]
    mean_velocity = 0.5 * (velocity[1:] + velocity[:-1])[pairs]
    # The motion's share: the trapezoid's error dt^2 jerk / 12, with dt^2 jerk read off the velocities'
    # second difference at either end of the pair (the larger).
    second = np.abs(np.diff(velocity, 2))
    motion = np.maximum(np.concatenate([[0.0], second]), np.concatenate([second, [0.0]]))[pairs] / 12.0
    scale = np.sqrt(
        (sp2[1:] + sp2[:-1])[pairs] / dt[pairs] ** 2 + 0.25 * (sv2[1:] + sv2[:-1])[pairs] + motion**2
    )
    z = (finite_difference - mean_velocity) / scale
    median_z = float(np.median(np.abs(z)))
    if not median_z > VELOCITY_Z:
        return None
    p_column, v_column = columns[:2]
    energy = float(np.sum(mean_velocity**2))
    ratio = float(np.sum(finite_difference * mean_velocity) / energy) if energy > 0 else float("nan")
    detail = (
        f"the velocity fixes disagree with the positions' finite differences (median |difference| "
        f"{median_z:.3g} times its standard deviation from the stated noise, about 0.67 expected; "
        f"finite difference / velocity = {ratio:.4g})"
    )
    for unit, factor in TIME_UNITS:
        # times in ``unit`` in both logs: dt reads ``factor`` times too long, the finite differences as much too small
        if abs(ratio * factor - 1) <= UNIT_TOLERANCE:
            t_column = columns[2] if len(columns) > 2 else "time"
            raise DataError(
                f"{source}: column {t_column!r}: {detail}: are the times of both logs in {unit} instead of seconds?"
            )
    for unit, factor in VELOCITY_UNITS:
        if abs(ratio / factor - 1) <= UNIT_TOLERANCE:
            raise DataError(f"{source}: column {v_column!r}: {detail}: is the velocity in {unit} instead of m/s?")
        if abs(ratio * factor - 1) <= UNIT_TOLERANCE:
            raise DataError(
                f"{source}: column {v_column!r}: {detail}: the velocity looks {1 / factor:.4g} times too small "
                f"(converted from {unit} to m/s twice?)"
            )
    return CalibrationWarning(
        "velocity-position-mismatch",
        f"{source}: columns {p_column!r} and {v_column!r}: {detail}: are both in SI units (m, m/s) and is the "
        "GPS noise setting right?",
    )


# --- unit slips that still give a number: the accelerometer in g or with gravity in, positions in mm or ft

#: standard gravity, m/s^2
STANDARD_GRAVITY = 9.80665
#: accelerometer units whose factor to m/s^2 a fitted ratio is tested against: a [m/s^2] = factor * a [unit]
ACCEL_UNITS = (("g", STANDARD_GRAVITY),)
#: position units whose factor a fitted ratio is tested against: p [unit] = factor * p [m]
POSITION_UNITS = (("millimetres", 1000.0), ("feet", 1 / 0.3048))
#: a fitted ratio within this relative distance of a unit's factor names that unit: wider than
#: :data:`UNIT_TOLERANCE`, for an integral of noisy samples is fitted, not a difference of fixes
SLIP_TOLERANCE = 0.05
#: ... and only when it lies this many standard errors from 1 (what SI units give): the fits' residuals
#: are not white (the bias drifts, the integrals carry the noise along), so their standard errors are
#: optimistic and the margin is wide
SLIP_Z = 10.0
#: a bias within this relative distance of g is gravity left in: g varies by 0.3 % over the Earth, a mount
#: tilted by 25 degrees reads 0.91 g, a MEMS bias is at most a few hundredths of g
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
    """Whether a fitted ``ratio`` (standard error ``se``) is the unit of ``factor``, not SI's 1."""
    return abs(ratio / factor - 1) <= SLIP_TOLERANCE and abs(ratio - 1) > SLIP_Z * se


def accelerometer_units(
    imu_time: np.ndarray,
    accel: np.ndarray,
    fix_time: np.ndarray,
    velocity: np.ndarray,
    imu_source: str,
    column: str = "accel",
) -> CalibrationWarning | None:
    """The accelerometer against the GPS velocities: its unit, and gravity left in.

    With I(t) the accelerometer integrated by the trapezoid rule (at the fix times, interpolated), the
    velocity fixes are fitted as v_f = k I(t_f) + v_0 - b t_f: a measured a [unit] = (a [m/s^2] + b) / k
    gives k = 1 for m/s^2 and k = g = 9.807 for an accelerometer in g (the integrated accelerometer is
    then 1/9.81 of the GPS velocity change). A k within :data:`SLIP_TOLERANCE` of a unit's factor
    (:data:`ACCEL_UNITS`), or of its inverse (converted twice), and :data:`SLIP_Z` standard errors from 1 is
    an error naming the unit. Otherwise, b is fitted with k = 1 (v_f - I(t_f) = v_0 - b t_f, which a log
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

    Returns
    -------
    CalibrationWarning or None
        ``gravity-in-accel`` when the bias is near +-g.

    Raises
    ------
    DataError
        When k names a unit.
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
        detail = (
            f"the GPS velocity changes are {k:.4g} times the integrated accelerometer (integrated "
            f"accelerometer / GPS velocity change = {1 / k:.4g})"
        )
        for unit, factor in ACCEL_UNITS:
            if _named_slip(k, se, factor):
                raise DataError(f"{imu_source}: column {column!r}: {detail}: is the acceleration in {unit} instead of m/s^2?")
            if _named_slip(k, se, 1 / factor):
                raise DataError(
                    f"{imu_source}: column {column!r}: {detail}: the acceleration looks {factor:.4g} times too large "
                    f"(converted from {unit} to m/s^2 twice?)"
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
    from 1 is an error naming the unit.

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
