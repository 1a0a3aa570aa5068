"""``kalcal calibrate``: read logs, run the filter, write estimates and a summary."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from kalcal.calibrate.accel_gps import calibrate_accel_gps
from kalcal.calibrate.diagnostics import innovation_diagnostics
from kalcal.calibrate.plausibility import CalibrationWarning
from kalcal.calibrate.smoothing import smooth_calibration
from kalcal.io.logs import numeric_columns, parse_column_map, read_table, require_increasing
from kalcal.io.outputs import writes_outputs
from kalcal.io.results import write_csv, write_json
from kalcal.models.accel_gps import AccelGpsScenario, AccelGpsSettings
from kalcal.models.config import section_values
from kalcal.plots.calibration import plot_calibration


IMU_ROLES = ("time", "accel")
GPS_ROLES = ("time", "position", "velocity", "position_std", "velocity_std")


def stated_rates(scenario: AccelGpsScenario) -> dict[str, float]:
    """``scenario.imu_rate`` and ``gps_rate`` where set to other than their defaults (200 Hz, 5 Hz): the
    rates the logs are then held to (Hz), as ``{"imu_rate": ..., "gps_rate": ...}``."""
    defaults = AccelGpsSettings()
    return {
        key: getattr(scenario.scenario, key)
        for key in ("imu_rate", "gps_rate")
        if getattr(scenario.scenario, key) != getattr(defaults, key)
    }


@writes_outputs(
    "calibrate accel-gps", names=("estimates.csv", "summary.json", "calibration.png"), inputs=("imu_path", "gps_path")
)
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
    form: str = "joseph",
    smooth: bool = False,
) -> dict[str, Any]:
    """Calibrate from an accelerometer log (time [s], accel [m/s^2]) and a GPS log (time [s], position [m],
    velocity [m/s], optionally position_std [m] and velocity_std [m/s] per fix).

    Writes ``out/estimates.csv`` (one row per fix used), ``out/summary.json`` and ``out/calibration.png``;
    returns the summary. Column names are mapped with ``"role=column,..."``. ``form`` is the filter's
    update form (joseph, standard or sqrt); ``smooth`` adds the RTS-smoothed states and their 1-sigma
    (``smoothed_position``, ..., ``smoothed_bias_std``) to ``estimates.csv`` and a ``smoothed`` object to
    ``summary.json``.

    Implausible logs are refused (:mod:`kalcal.calibrate.plausibility`); the summary's ``warnings`` is a
    list of ``{"code", "message"}`` (empty when none), and ``fixes_default_std`` counts the fixes used whose
    ``position_std`` / ``velocity_std`` was NaN and took the filter's setting.
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
        form=form,
        source=str(gps_path),
        imu_source=str(imu_path),
        **stated_rates(scenario),
        columns={**{role: gps_map[role] for role in GPS_ROLES}, "imu_time": imu_map["time"], "accel": imu_map["accel"]},
    )
    std = result.std
    normalized = result.normalized_innovations
    out = Path(out)
    smoothed = smooth_calibration(result) if smooth else None
    smoothed_columns = {}
    if smoothed is not None:
        smoothed_std = smoothed.std
        names = scenario.state_names
        smoothed_columns = {
            **{f"smoothed_{name}": getattr(smoothed, name) for name in names},
            **{f"smoothed_{name}_std": smoothed_std[:, i] for i, name in enumerate(names)},
        }
    write_csv(
        out / "estimates.csv",
        {
            "time": result.time,
            "position": result.position,
            "velocity": result.velocity,
            "bias": result.bias,
            **({"scale": result.error_state[:, 3]} if scenario.has_scale else {}),
            **{f"{name}_std": std[:, i] for i, name in enumerate(scenario.state_names)},
            "nis": result.nis,
            "innovation_position": normalized[:, 0],
            "innovation_velocity": normalized[:, 1],
            **smoothed_columns,
        },
    )
    diagnostics = innovation_diagnostics(normalized)
    warnings = list(result.warnings)
    if result.skipped_nan:
        warnings.append(CalibrationWarning("fixes-skipped-nan", f"{result.skipped_nan} fix(es) with a NaN field skipped"))
    if result.skipped_outside:
        warnings.append(
            CalibrationWarning(
                "fixes-skipped-outside", f"{result.skipped_outside} fix(es) outside the accelerometer log skipped"
            )
        )
    if result.gaps:
        longest = max(result.gaps, key=lambda gap: gap.length)
        warnings.append(
            CalibrationWarning(
                "imu-gaps",
                f"{len(result.gaps)} accelerometer gap(s) longer than {max_imu_gap:g} sample periods, the longest "
                f"{longest.length:.6g} s after t = {longest.start:.9g} s (row {longest.row})",
            )
        )
    summary = {
        "scenario": scenario.NAME,
        "settings": section_values(scenario),
        "imu": str(imu_path),
        "gps": str(gps_path),
        "init": result.init,
        "form": result.form,
        "start_time": result.start_time,
        "fixes_used": int(result.time.size),
        "fixes_skipped_nan": result.skipped_nan,
        "fixes_skipped_outside": result.skipped_outside,
        "fixes_default_std": result.default_std,
        "imu_gaps": [gap.__dict__ for gap in result.gaps],
        "time": float(result.time[-1]),
        "bias": float(result.bias[-1]),
        "bias_std": float(std[-1, 2]),
        "position": float(result.position[-1]),
        "position_std": float(std[-1, 0]),
        "velocity": float(result.velocity[-1]),
        "velocity_std": float(std[-1, 1]),
        "covariance": result.covariance[-1],
        "covariance_states": list(scenario.state_names),
        "diagnostics": diagnostics.as_dict(),
        "warnings": [warning.as_dict() for warning in warnings],
        "units": {"time": "s", **dict(zip(scenario.state_names, scenario.state_units))},
    }
    if scenario.has_scale:
        summary["scale"], summary["scale_std"] = float(result.error_state[-1, 3]), float(std[-1, 3])
    if smoothed is not None:
        summary["smoothed"] = _smoothed_summary(smoothed, std, scenario.state_names)
    write_json(out / "summary.json", summary)
    plot_calibration(result.time, result.bias, std[:, 2], normalized, out / "calibration.png")
    return summary


def _smoothed_summary(smoothed, filter_std, names: tuple[str, ...]) -> dict[str, Any]:
    """The smoothed estimates at the first fix (where smoothing gains most; at the last fix they equal
    the filter's) and, per state, the mean of smoothed sigma / filter sigma over the fixes."""
    std = smoothed.std
    summary: dict[str, Any] = {"method": "rts", "time": float(smoothed.time[0])}
    for i, name in enumerate(names):
        summary[name] = float(getattr(smoothed, name)[0])
        summary[f"{name}_std"] = float(std[0, i])
    summary["covariance"] = smoothed.covariance[0]
    summary["covariance_states"] = list(names)
    summary["mean_std_ratio"] = {name: float(np.mean(std[:, i] / filter_std[:, i])) for i, name in enumerate(names)}
    return summary
