"""What an accelerometer log and a GPS log must pass before filtering, and what their fixes need said."""

from __future__ import annotations

import numpy as np

from kalcal.calibration import plausibility, unit_slips as slips
from kalcal.calibration.plausibility import CalibrationWarning

__all__ = ["check_plausible", "fix_warnings", "unit_slips"]


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
    plausibility.check_imu_faster(rate, fix_rate, imu_source)
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
    mismatch = plausibility.velocity_consistency(
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
