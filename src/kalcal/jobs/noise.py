"""``kalcal noise``: read a static accelerometer log, identify its noise, write the summary, curve, plot and
the matching ``[filter]`` settings."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from kalcal.calibrate.allan import regular_rate
from kalcal.calibrate.noise import NoiseIdentification, identify_noise
from kalcal.calibrate.plausibility import CalibrationWarning, check_limit, check_rate
from kalcal.errors import DataError
from kalcal.io.logs import numeric_columns, parse_column_map, read_table, require_increasing
from kalcal.io.outputs import final_path, writes_outputs
from kalcal.io.results import write_csv, write_json
from kalcal.models.accel_gps import AccelGpsFilter
from kalcal.plots.allan import plot_allan

IMU_ROLES = ("time", "accel")
#: the identified values that map onto accel-gps ``filter.`` settings of the same name
FILTER_KEYS = ("accel_noise_std", "bias_walk_std")


def filter_settings(result: NoiseIdentification) -> dict[str, float]:
    """The ``[filter]`` settings the identification gives: each identified value whose key accel-gps accepts."""
    accepted = {f.name for f in dataclasses.fields(AccelGpsFilter)}
    values = {key: getattr(result, key).value for key in FILTER_KEYS}
    # A TOML number written with 6 significant digits, read back as the same float.
    return {key: float(f"{value:.6g}") for key, value in values.items() if value is not None and key in accepted}


def filter_toml(result: NoiseIdentification, settings: dict[str, float], source: str) -> str:
    """A TOML snippet for ``kalcal calibrate accel-gps --config``: ``[filter]`` with ``settings``, commented."""
    rate = result.rate
    lines = [
        f"# kalcal noise: accelerometer noise identified from {source}",
        f"# ({result.samples} samples at {rate:.6g} Hz, {result.duration:.6g} s). Per-sample values hold at {rate:.6g} Hz;",
        "# for a log at another rate f: accel_noise_std = N sqrt(f), bias_walk_std = K / sqrt(f).",
    ]
    vrw, rrw = result.velocity_random_walk, result.rate_random_walk
    if vrw.identified:
        lines.append(f"# N = {vrw.value:.6g} {vrw.unit} (velocity random walk)")
    if result.bias_instability.identified:
        b = result.bias_instability
        lines.append(f"# B = {b.value:.6g} {b.unit} (bias instability; no filter setting of its own)")
    if rrw.identified:
        lines.append(f"# K = {rrw.value:.6g} {rrw.unit} (rate random walk)")
    for key in FILTER_KEYS:
        if key not in settings:
            parameter = getattr(result, key)
            why = parameter.note if not parameter.identified else "the accel-gps filter has no such setting"
            lines.append(f"# {key}: not written ({why})")
    lines += ["", "[filter]"]
    lines += [f"{key} = {value!r}" for key, value in settings.items()]
    return "\n".join(lines) + "\n"


@writes_outputs("noise", names=("summary.json", "allan.csv", "allan.png", "filter.toml"), inputs=("imu_path",))
def identify_noise_file(
    imu_path: str | Path,
    out: str | Path,
    *,
    imu_columns: str | None = None,
    confidence: float = 0.95,
    strict: bool = False,
) -> dict[str, Any]:
    """Identify the noise of a static accelerometer log (time [s], accel [m/s^2]; CSV or Parquet).

    Writes ``out/summary.json``, ``out/allan.csv`` (tau [s], adev and its bounds [m/s^2], edf, noise type),
    ``out/allan.png`` and ``out/filter.toml``; returns the summary. The log must be evenly sampled (steps
    within 1% of the median step), at a plausible accelerometer rate, with every sample within the physical
    limit (:mod:`kalcal.calibrate.plausibility`). Columns are mapped with ``"time=t,accel=ax"``. A log that
    does not look static (:func:`~kalcal.calibrate.motion.motion_warnings`) is flagged in the summary's
    ``warnings`` (``{"code", "message"}`` each, empty when none) and at the top of ``filter.toml``; with
    ``strict`` it is refused (DataError) before anything is written.
    """
    imu_map = parse_column_map(imu_columns, IMU_ROLES, "--imu-columns")
    frame = read_table(imu_path)
    imu = numeric_columns(frame, imu_path, imu_map)
    time, accel = imu["time"], imu["accel"]
    require_increasing(time, imu_path, imu_map["time"])
    rate = regular_rate(time, str(imu_path), imu_map["time"])
    check_rate(time, "accelerometer", str(imu_path), imu_map["time"])
    check_limit(time, "time", str(imu_path), imu_map["time"])
    check_limit(accel, "accel", str(imu_path), imu_map["accel"])  # "row N, column 'accel'" as in calibrate
    try:
        result = identify_noise(accel, rate, confidence, duration=float(time[-1] - time[0]))
    except DataError as exc:
        raise DataError(f"{imu_path}: column {imu_map['accel']!r}: {exc}") from None
    warnings = [CalibrationWarning(w.code, f"{imu_path}: {w.message}") for w in result.warnings]
    if strict and warnings:
        raise DataError(f"{warnings[0].message} (--strict: refused, nothing written)")

    out = Path(out)
    settings = filter_settings(result)
    curve = result.curve
    paths = {
        "summary": out / "summary.json",
        "allan": out / "allan.csv",
        "plot": out / "allan.png",
        "filter": out / "filter.toml",
    }
    write_csv(
        paths["allan"],
        {
            "tau": curve.tau,
            "adev": curve.adev,
            "adev_low": curve.low,
            "adev_high": curve.high,
            "edf": curve.edf,
            "alpha": curve.alpha,
            "alpha_identified": curve.alpha_identified,
            "terms": curve.terms,
        },
    )
    plot_allan(result, paths["plot"], title=f"kalcal noise: {Path(imu_path).name}")
    flagged = "".join(f"# WARNING: {w.message}\n" for w in warnings)
    paths["filter"].write_text(flagged + filter_toml(result, settings, str(imu_path)))
    summary = {
        "imu": str(imu_path),
        "columns": imu_map,
        "samples": result.samples,
        "rate": {"value": result.rate, "unit": "Hz", "note": "median sample rate"},
        "sample_period": {"value": result.sample_period, "unit": "s"},
        "duration": {"value": result.duration, "unit": "s"},
        "mean": {"value": result.mean, "unit": "m/s^2", "note": "constant bias plus any gravity component"},
        "std": {"value": result.std, "unit": "m/s^2", "note": "of the samples about their mean"},
        "confidence": confidence,
        **{parameter.name: parameter.as_dict() for parameter in result.parameters},
        "filter": settings,
        "notes": [
            f"{p.name}: {p.note}"
            for p in (result.velocity_random_walk, result.bias_instability, result.rate_random_walk)
            if not p.identified
        ],
        "allan": {
            "tau": curve.tau,
            "adev": curve.adev,
            "ci_low": curve.low,
            "ci_high": curve.high,
            "edf": curve.edf,
            "alpha": curve.alpha,
            "alpha_identified": curve.alpha_identified,
            "terms": curve.terms,
            "units": {"tau": "s", "adev": "m/s^2"},
        },
        "files": {name: str(final_path(path)) for name, path in paths.items()},
        "warnings": [warning.as_dict() for warning in warnings],
    }
    write_json(paths["summary"], summary)
    return summary
