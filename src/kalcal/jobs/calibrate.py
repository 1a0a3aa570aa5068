"""``kalcal calibrate``: read logs, run the filter, write estimates and a summary."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from kalcal.calibrate.accel_gps import calibrate_accel_gps
from kalcal.errors import DataError
from kalcal.io.logs import numeric_columns, read_table, require_increasing
from kalcal.io.results import write_csv, write_json
from kalcal.models.accel_gps import STATE_NAMES, AccelGpsScenario
from kalcal.models.config import section_values


def calibrate_accel_gps_files(
    scenario: AccelGpsScenario, imu_path: str | Path, gps_path: str | Path, out: str | Path
) -> dict[str, Any]:
    """Calibrate from ``imu`` (time, accel) and ``gps`` (time, position, velocity) logs.

    Writes ``out/estimates.csv`` (one row per fix) and ``out/summary.json``; returns the summary.
    """
    imu = numeric_columns(read_table(imu_path), imu_path, ("time", "accel"))
    gps = numeric_columns(read_table(gps_path), gps_path, ("time", "position", "velocity"))
    require_increasing(imu["time"], imu_path)
    require_increasing(gps["time"], gps_path)
    if imu["time"].size < 2:
        raise DataError(f"{imu_path}: needs at least two accelerometer samples, got {imu['time'].size}")
    result = calibrate_accel_gps(
        scenario,
        imu["time"],
        imu["accel"],
        gps["time"],
        gps["position"],
        gps["velocity"],
        source=str(gps_path),
        imu_source=str(imu_path),
    )
    std = result.std
    out = Path(out)
    write_csv(
        out / "estimates.csv",
        {
            "time": result.time,
            "position": result.position,
            "velocity": result.velocity,
            "bias": result.bias,
            **{f"{name}_std": std[:, i] for i, name in enumerate(STATE_NAMES)},
        },
    )
    summary = {
        "scenario": scenario.NAME,
        "settings": section_values(scenario),
        "imu": str(imu_path),
        "gps": str(gps_path),
        "fixes_used": int(result.time.size),
        "time": float(result.time[-1]),
        "bias": float(result.bias[-1]),
        "bias_std": float(std[-1, 2]),
        "position": float(result.position[-1]),
        "position_std": float(std[-1, 0]),
        "velocity": float(result.velocity[-1]),
        "velocity_std": float(std[-1, 1]),
        "covariance": result.covariance[-1],
        "covariance_states": list(STATE_NAMES),
        "units": {"time": "s", "position": "m", "velocity": "m/s", "bias": "m/s^2"},
    }
    write_json(out / "summary.json", summary)
    return summary
