"""``kalcal calibrate``: read logs, run the filter, write estimates and a summary."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from kalcal.calibrate.accel_gps import calibrate_accel_gps
from kalcal.calibrate.diagnostics import innovation_diagnostics
from kalcal.io.logs import numeric_columns, parse_column_map, read_table, require_increasing
from kalcal.io.results import write_csv, write_json
from kalcal.models.accel_gps import STATE_NAMES, AccelGpsScenario
from kalcal.models.config import section_values
from kalcal.plots.calibration import plot_calibration


IMU_ROLES = ("time", "accel")
GPS_ROLES = ("time", "position", "velocity", "position_std", "velocity_std")


def calibrate_accel_gps_files(
    scenario: AccelGpsScenario,
    imu_path: str | Path,
    gps_path: str | Path,
    out: str | Path,
    *,
    imu_columns: str | None = None,
    gps_columns: str | None = None,
    init: str = "first-fix",
    max_imu_gap: float = 5.0,
    stop_on_gap: bool = False,
) -> dict[str, Any]:
    """Calibrate from an accelerometer log (time [s], accel [m/s^2]) and a GPS log (time [s], position [m],
    velocity [m/s], optionally position_std [m] and velocity_std [m/s] per fix).

    Writes ``out/estimates.csv`` (one row per fix used), ``out/summary.json`` and ``out/calibration.png``;
    returns the summary. Column names are mapped with ``"role=column,..."``.
    """
    imu_map = parse_column_map(imu_columns, IMU_ROLES, "--imu-columns")
    gps_map = parse_column_map(gps_columns, GPS_ROLES, "--gps-columns")
    imu_frame, gps_frame = read_table(imu_path), read_table(gps_path)
    imu = numeric_columns(imu_frame, imu_path, imu_map)
    optional = [role for role in ("position_std", "velocity_std") if gps_map[role] in gps_frame.columns]
    gps = numeric_columns(
        gps_frame,
        gps_path,
        {role: gps_map[role] for role in ("time", "position", "velocity", *optional)},
        allow_nan=("position", "velocity", *optional),
    )
    require_increasing(imu["time"], imu_path, imu_map["time"])
    require_increasing(gps["time"], gps_path, gps_map["time"])
    result = calibrate_accel_gps(
        scenario,
        imu["time"],
        imu["accel"],
        gps["time"],
        gps["position"],
        gps["velocity"],
        position_std=gps.get("position_std"),
        velocity_std=gps.get("velocity_std"),
        init=init,
        max_imu_gap=max_imu_gap,
        stop_on_gap=stop_on_gap,
        source=str(gps_path),
        imu_source=str(imu_path),
    )
    std = result.std
    normalized = result.normalized_innovations
    out = Path(out)
    write_csv(
        out / "estimates.csv",
        {
            "time": result.time,
            "position": result.position,
            "velocity": result.velocity,
            "bias": result.bias,
            **{f"{name}_std": std[:, i] for i, name in enumerate(STATE_NAMES)},
            "nis": result.nis,
            "innovation_position": normalized[:, 0],
            "innovation_velocity": normalized[:, 1],
        },
    )
    diagnostics = innovation_diagnostics(normalized)
    warnings = []
    if result.skipped_nan:
        warnings.append(f"{result.skipped_nan} fix(es) with a NaN field skipped")
    if result.skipped_outside:
        warnings.append(f"{result.skipped_outside} fix(es) outside the accelerometer log skipped")
    if result.gaps:
        longest = max(result.gaps, key=lambda gap: gap.length)
        warnings.append(
            f"{len(result.gaps)} accelerometer gap(s) longer than {max_imu_gap:g} sample periods, the longest "
            f"{longest.length:.6g} s after t = {longest.start:.9g} s (row {longest.row})"
        )
    summary = {
        "scenario": scenario.NAME,
        "settings": section_values(scenario),
        "imu": str(imu_path),
        "gps": str(gps_path),
        "init": result.init,
        "start_time": result.start_time,
        "fixes_used": int(result.time.size),
        "fixes_skipped_nan": result.skipped_nan,
        "fixes_skipped_outside": result.skipped_outside,
        "imu_gaps": [gap.__dict__ for gap in result.gaps],
        "time": float(result.time[-1]),
        "bias": float(result.bias[-1]),
        "bias_std": float(std[-1, 2]),
        "position": float(result.position[-1]),
        "position_std": float(std[-1, 0]),
        "velocity": float(result.velocity[-1]),
        "velocity_std": float(std[-1, 1]),
        "covariance": result.covariance[-1],
        "covariance_states": list(STATE_NAMES),
        "diagnostics": diagnostics.as_dict(),
        "warnings": warnings,
        "units": {"time": "s", "position": "m", "velocity": "m/s", "bias": "m/s^2"},
    }
    write_json(out / "summary.json", summary)
    plot_calibration(result.time, result.bias, std[:, 2], normalized, out / "calibration.png")
    return summary
