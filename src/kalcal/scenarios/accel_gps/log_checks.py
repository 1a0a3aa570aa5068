"""What an accelerometer log and a GPS log must pass before filtering, and what their fixes need said.

Each log alone passes the checks every sensor's log does (:mod:`kalcal.calibration.plausibility`: rates,
physical limits); what holds between the two is accel-gps's own and is here: the accelerometer samples
faster than the fixes (:func:`check_imu_faster`), the velocity fixes agree with the positions' finite
differences (:func:`velocity_consistency`), and the unit slips that only a fit across the logs names
(:mod:`kalcal.scenarios.accel_gps.unit_slips`).
"""

from __future__ import annotations

import numpy as np

from collections.abc import Mapping, Sequence

from kalcal.calibration import plausibility
from kalcal.calibration.plausibility import CalibrationWarning
from kalcal.errors import DataError
from kalcal.scenarios.accel_gps import unit_slips as slips
from kalcal.scenarios.accel_gps.settings import DENSITIES, DENSITY_UNITS, density_of

__all__ = [
    "NOISE_RATE_TOLERANCE", "check_imu_faster", "check_plausible", "fix_warnings", "noise_rate_warnings",
    "unit_slips", "velocity_consistency",
]

#: velocity units whose factor to m/s the fitted ratio is tested against: v [m/s] = factor * v [unit]
VELOCITY_UNITS = (("km/h", 1 / 3.6), ("mph", 0.44704), ("knots", 1852 / 3600))
#: a fitted ratio within this relative distance of a unit's factor names that unit
UNIT_TOLERANCE = 0.02
#: median |z| of velocity minus finite difference above which the fixes disagree grossly (0.67 expected)
VELOCITY_Z = 5.0
#: pairs of fixes farther apart than this many median fix intervals are not compared (an outage)
PAIR_SPAN = 1.5


#: a per-sample noise setting written for a rate this close (relative) to the log's is taken as written
#: for it: its std is then off by at most half as much (0.5%)
NOISE_RATE_TOLERANCE = 0.01


def check_plausible(
    imu_time, accel, gps_time, position, velocity, position_std, velocity_std,
    source: str, imu_source: str, imu_rate: float | None, gps_rate: float | None, columns: dict[str, str],
) -> None:
    """Refuse implausible logs (DataError): rates, then every value against its physical limit (fix times
    excepted: a fix outside the accelerometer log is skipped and counted)."""

    def name(role: str, default: str | None = None) -> str:
        return columns.get(role, default or role)

    rate = plausibility.check_rate(
        imu_time, "accelerometer", imu_source, name("imu_time", "time"), expected=imu_rate, setting="scenario.imu_rate"
    )
    fix_rate = plausibility.check_rate(gps_time, "gnss", source, name("time"), expected=gps_rate, setting="scenario.gps_rate")
    check_imu_faster(rate, fix_rate, imu_source)
    checks = [
        (imu_time, "time", imu_source, name("imu_time", "time")),
        (accel, "accel", imu_source, name("accel")),
        (position, "position", source, name("position")),
        (velocity, "velocity", source, name("velocity")),
        (position_std, "position", source, name("position_std")),
        (velocity_std, "velocity", source, name("velocity_std")),
    ]
    for values, quantity, log, column in checks:
        if values is not None:
            plausibility.check_limit(values, quantity, log, column)


def fix_warnings(
    usable, gps_time, position, velocity, std_p, std_v, nan_std_p, nan_std_v, settings, source: str,
    columns: dict[str, str], positions: bool = True,
) -> list[CalibrationWarning]:
    """What the fixes used need said: per-fix stds that were NaN, velocities that disagree with positions
    (``positions=False``, velocity-only fixes: the velocity column's NaN stds only)."""
    warnings = []
    for role, nan, default in (
        ("position_std", nan_std_p, settings.gps_position_std),
        ("velocity_std", nan_std_v, settings.gps_velocity_std),
    )[0 if positions else 1 :]:
        count = int(np.count_nonzero(nan[usable]))
        if count:
            warnings.append(
                CalibrationWarning(
                    "default-fix-std",
                    f"{source}: column {columns.get(role, role)!r}: {count} fix(es) used have no value (NaN) and "
                    f"took the filter's setting {default:g}",
                )
            )
    if not positions:
        return warnings
    mismatch = velocity_consistency(
        gps_time[usable], position[usable], velocity[usable], std_p[usable], std_v[usable], source,
        (columns.get("position", "position"), columns.get("velocity", "velocity"), columns.get("time", "time")),
    )
    return warnings + ([mismatch] if mismatch is not None else [])


def unit_slips(
    imu_time, accel, usable, gps_time, position, velocity, source: str, imu_source: str, columns: dict[str, str],
    positions: bool = True,
) -> list[CalibrationWarning]:
    """Unit slips that still give a number, over the usable fixes: positions in mm or ft, an accelerometer
    in g, a GPS log wholly in mm or ft (DataError naming the unit), gravity left in the accelerometer (a
    warning). ``positions=False`` (velocity-only fixes): the positions' units are not checked."""
    time, position, velocity = (np.asarray(a, dtype=float)[usable] for a in (gps_time, position, velocity))
    if positions:
        slips.position_units(time, position, velocity, source, columns.get("position", "position"))
    gravity = slips.accelerometer_units(
        imu_time, accel, time, velocity, imu_source, columns.get("accel", "accel"), gps_source=source
    )
    return [gravity] if gravity is not None else []


def noise_rate_warnings(
    per_sample: Mapping[str, tuple[float, str | None]], recorded: Mapping[str, float | None], rate: float, source: str
) -> list[CalibrationWarning]:
    """Warnings for noise settings given per sample (``filter.accel_noise_std``, ``filter.bias_walk_std``
    or the truth's they fall back to), applied as they stand at a log's rate.

    A per-sample std holds at one rate only (:func:`~kalcal.scenarios.accel_gps.settings.per_sample`): the white
    noise's is N sqrt(f), the bias walk's step K / sqrt(f). Applied at a log's rate ``rate`` when written
    for ``recorded`` Hz, the white noise's std is sqrt(recorded / rate) of the right one (0.71 for 100 Hz
    settings on a 200 Hz log) and the walk's sqrt(rate / recorded): a warning naming both rates
    (``noise-rate-mismatch``) where they differ by more than :data:`NOISE_RATE_TOLERANCE`. Where no rate is
    recorded (a filter.toml of ``kalcal noise`` from before the densities names it in a comment only), a
    warning that the rate cannot be checked (``noise-rate-unknown``) for a value read from a file; a value
    given with ``--set`` or in code is taken as given for the log at hand. A file's value has a recorded
    rate only where the same file gives ``scenario.imu_rate``: ``--set scenario.imu_rate=...`` does not
    make an old file's rate known, and replacing a file's rate there does not make it unknown (the file's own
    rate is kept apart, :func:`kalcal.models.config.file_settings`). Both name the density to give instead.

    Parameters
    ----------
    per_sample : mapping of str to (float, str or None)
        The settings given per sample, by key, m/s^2, and the file each was read from
        (:meth:`AccelGpsScenario.per_sample_settings`).
    recorded : mapping of str to float or None
        The rate recorded for each, by key, Hz (None where none is).
    rate : float
        The log's median accelerometer rate, Hz.
    source : str
        The accelerometer log, quoted.
    """
    warnings = []
    for key, (value, file) in per_sample.items():
        at = recorded.get(key)
        section, name = key.split(".", 1)
        density_key = f"{section}.{DENSITIES[name][0]}"
        unit = DENSITY_UNITS[DENSITIES[name][0]]
        where = f"{file}: " if file else ""
        if at is None and file is not None:
            warnings.append(CalibrationWarning(
                "noise-rate-unknown",
                f"{where}{key} = {value:.6g} m/s^2 is a per-sample value and no rate is recorded for it "
                f"(its file gives no scenario.imu_rate; a filter.toml of kalcal noise from before the densities names "
                f"its rate in a comment only): it is applied per sample at {source}'s {rate:.6g} Hz, which "
                f"cannot be checked. Give {density_key} (rate-free, {unit}) instead",
            ))
        elif at is not None and abs(rate / at - 1) > NOISE_RATE_TOLERANCE:
            density = density_of(name, value, at)
            ratio = value / (density * rate ** DENSITIES[name][1])
            warnings.append(CalibrationWarning(
                "noise-rate-mismatch",
                f"{where}{key} = {value:.6g} m/s^2 per sample was written for {at:.6g} Hz "
                f"(scenario.imu_rate), but {source} samples at {rate:.6g} Hz: applied as it stands it is "
                f"{ratio:.3g} times the std the same noise has per sample at {rate:.6g} Hz. Give "
                f"{density_key} = {density:.6g} {unit} (rate-free) instead",
            ))
    return warnings


def check_imu_faster(imu_rate: float, gps_rate: float, imu_source: str) -> None:
    """Refuse an accelerometer that samples less often than the GPS fixes (its times likely in ms)."""
    if np.isfinite(gps_rate) and imu_rate < gps_rate * (1 - plausibility.RATE_MARGIN):
        low, high = max(plausibility.IMU_RATE_RANGE[0], gps_rate), plausibility.IMU_RATE_RANGE[1]
        raise DataError(
            f"{imu_source}: accelerometer sample rate {imu_rate:.6g} Hz is below the GPS fix rate {gps_rate:.6g} Hz "
            f"(the accelerometer is the fast sensor){plausibility.unit_hint(imu_rate, low, high, 200.0)}"
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
    for unit, factor in plausibility.TIME_UNITS:
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
