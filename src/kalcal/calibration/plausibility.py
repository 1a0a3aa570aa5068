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
:data:`HINT_MARGIN` inside (a unit slip moves a rate by 60 or more; a rate just beyond a bound is not one).

What holds between one scenario's logs (accel-gps: the accelerometer faster than the fixes, the velocity
fixes against the positions, unit slips fitted across the two logs) is that scenario's
(:mod:`kalcal.scenarios.accel_gps.log_checks`); this module holds what any sensor's log must pass.
"""

from __future__ import annotations

from dataclasses import dataclass, field

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


@dataclass(frozen=True)
class CalibrationWarning:
    """Something a calibration's user must know: a short stable ``code`` and a one-line ``message``.

    ``next_step`` is the command or change the message names as the next step, where it names one (the
    ``sigma-untrusted`` warning's fit); it is part of ``message`` and is not written apart: ``summary.json``'s
    ``warnings`` hold ``{"code", "message"}`` each (:meth:`to_dict`).
    """

    code: str
    message: str
    next_step: str | None = field(default=None, compare=False)

    def to_dict(self) -> dict[str, str]:
        """``{"code", "message"}``, as ``summary.json``'s ``warnings`` hold it."""
        return {"code": self.code, "message": self.message}

    as_dict = to_dict


def median_rate(time: np.ndarray) -> float:
    """1 / the median interval of strictly increasing ``time`` (s), Hz; NaN for fewer than
    :data:`MIN_RATE_SAMPLES` samples (too few intervals for a median to mean a rate)."""
    time = np.asarray(time, dtype=float)
    return float(1.0 / np.median(np.diff(time))) if time.size >= MIN_RATE_SAMPLES else float("nan")


def _within(rate: float, low: float, high: float) -> bool:
    """``low <= rate <= high`` to a relative :data:`RATE_MARGIN` at either bound."""
    return low * (1 - RATE_MARGIN) <= rate <= high * (1 + RATE_MARGIN)


def unit_hint(rate: float, low: float, high: float, typical: float, inside: float = HINT_MARGIN) -> str:
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
            f"(expected {low:g} Hz to {high:g} Hz){unit_hint(rate, low, high, typical)}"
        )
    if expected is not None and not _within(rate, expected / RATE_FACTOR, expected * RATE_FACTOR):
        raise DataError(
            f"{source}: column {column!r}: {name} {rate:.6g} Hz differs from {setting or 'the set rate'} = "
            f"{expected:g} Hz by more than a factor {RATE_FACTOR:g}"
            f"{unit_hint(rate, expected / RATE_FACTOR, expected * RATE_FACTOR, expected, inside=1.0)}"
        )
    return rate


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
