"""What an accelerometer log and a GPS log must pass before filtering, and what their fixes need said."""

from __future__ import annotations

import numpy as np

from collections.abc import Mapping

from kalcal.calibration import plausibility, unit_slips as slips
from kalcal.calibration.plausibility import CalibrationWarning
from kalcal.scenarios.accel_gps.settings import DENSITIES, DENSITY_UNITS, density_of

__all__ = ["NOISE_RATE_TOLERANCE", "check_plausible", "fix_warnings", "noise_rate_warnings", "unit_slips"]

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
