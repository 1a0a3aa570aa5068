"""``kalcal noise``: a static accelerometer log's noise identified in memory, then written as one set.

It writes the summary, the Allan curve and plot, the matching ``[filter]`` settings (rate-free densities,
converted by ``calibrate`` at each log's own rate) and Kalibr's imu.yaml.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from kalcal.calibration.allan import regular_rate
from kalcal.calibration.noise import NoiseIdentification, identify_noise
from kalcal.calibration.plausibility import CalibrationWarning, check_limit, check_rate
from kalcal.errors import DataError
from kalcal.io.logs import numeric_columns, parse_column_map, read_table, require_increasing, source_name
from kalcal.io.outputs import final_path, inputs_of, mark_inputs, run_outputs
from kalcal.io.results import write_json
from kalcal.models.accel_gps import AccelGpsFilter, per_sample

IMU_ROLES = ("time", "accel")
#: each accel-gps ``filter.`` density the identification gives, the identified value it is (N, K), and
#: the per-sample value it gives at the log's rate (written in a comment and in summary.json only: a
#: per-sample value holds at one rate, a density at every rate)
FILTER_KEYS = {
    "accel_noise_density": ("velocity_random_walk", "accel_noise_std"),
    "bias_walk_density": ("rate_random_walk", "bias_walk_std"),
}


def filter_settings(result: NoiseIdentification) -> dict[str, float]:
    """The ``[filter]`` settings the identification gives: the density of each identified noise whose key
    accel-gps accepts (``accel_noise_density`` = N, ``bias_walk_density`` = K)."""
    accepted = {f.name for f in dataclasses.fields(AccelGpsFilter)}
    values = {key: getattr(result, name).value for key, (name, _) in FILTER_KEYS.items()}
    # A TOML number written with 6 significant digits, read back as the same float.
    return {key: float(f"{value:.6g}") for key, value in values.items() if value is not None and key in accepted}


def per_sample_settings(result: NoiseIdentification, settings: dict[str, float]) -> dict[str, Any]:
    """summary.json's ``per_sample``: each written density's per-sample value at the log's rate (m/s^2),
    what ``calibrate`` uses on a log at that rate (at another it converts the density anew)."""
    values = {FILTER_KEYS[key][1]: per_sample(FILTER_KEYS[key][1], value, result.rate) for key, value in settings.items()}
    return {
        "rate": result.rate,
        "unit": "m/s^2",
        **values,
        "note": (
            f"per sample at this log's {result.rate:.6g} Hz, from the densities in [filter]: accel_noise_std = N sqrt(rate), "
            "bias_walk_std = K / sqrt(rate); calibrate converts the densities at each log's own rate"
        ),
    }


def filter_toml(result: NoiseIdentification, settings: dict[str, float], source: str) -> str:
    """A TOML snippet for ``kalcal calibrate accel-gps --config``: ``[filter]`` with the densities in
    ``settings``, commented with their per-sample values at the log's rate."""
    rate = result.rate
    lines = [
        f"# kalcal noise: accelerometer noise identified from {source}",
        f"# ({result.samples} samples at {rate:.6g} Hz, {result.duration:.6g} s). [filter] holds rate-free densities:",
        "# calibrate converts them at each log's own rate f (accel_noise_std = N sqrt(f), bias_walk_std = K / sqrt(f)),",
        "# assuming each sample averages over its period (docs/noise.md: a log decimated without averaging).",
    ]
    vrw, rrw = result.velocity_random_walk, result.rate_random_walk
    if vrw.identified:
        lines.append(f"# N = {vrw.value:.6g} {vrw.unit} (velocity random walk)")
    if result.bias_instability.identified:
        b = result.bias_instability
        lines.append(f"# B = {b.value:.6g} {b.unit} (bias instability; no filter setting of its own)")
    if rrw.identified:
        lines.append(f"# K = {rrw.value:.6g} {rrw.unit} (rate random walk)")
    for key, (name, sample_name) in FILTER_KEYS.items():
        if key in settings:
            value = per_sample(sample_name, settings[key], rate)
            lines.append(f"# {key}: {sample_name} = {value:.6g} m/s^2 per sample at {rate:.6g} Hz (this log's rate)")
        else:
            parameter = getattr(result, name)
            why = parameter.note if not parameter.identified else "the accel-gps filter has no such setting"
            lines.append(f"# {key}: not written ({why})")
    lines += ["", "[filter]"]
    lines += [f"{key} = {value!r}" for key, value in settings.items()]
    return "\n".join(lines) + "\n"


#: the files of ``kalcal noise`` (and :data:`KALIBR_NAME` unless it is left out)
OUTPUT_NAMES = ("summary.json", "allan.csv", "allan.png", "filter.toml")
#: the Kalibr noise file, written beside filter.toml by default
KALIBR_NAME = "imu.yaml"


def output_names(kalibr: bool = True) -> tuple[str, ...]:
    """The files of one ``kalcal noise`` run: :data:`OUTPUT_NAMES`, with ``kalibr`` :data:`KALIBR_NAME` too."""
    return (*OUTPUT_NAMES, KALIBR_NAME) if kalibr else OUTPUT_NAMES


@dataclass(frozen=True)
class NoiseRun:
    """A noise identification computed in memory, nothing written yet (:func:`compute_noise`).

    Attributes
    ----------
    identification : NoiseIdentification
        N, B, K and the per-sample values with their intervals, and the Allan curve.
    summary : dict
        ``summary.json``'s content but its ``files`` (where :func:`save_noise` writes them).
    filter_text : str
        ``filter.toml``: the ``[filter]`` settings for ``kalcal calibrate accel-gps --config``.
    allan : pandas.DataFrame
        ``allan.csv``: tau [s], adev and its bounds [m/s^2], edf, noise type.
    title : str
        The Allan plot's title.
    """

    identification: NoiseIdentification
    summary: dict[str, Any]
    filter_text: str
    allan: pd.DataFrame
    title: str


def save_noise(run: NoiseRun, out: str | Path, *, kalibr: bool = True) -> dict[str, Any]:
    """Write ``summary.json``, ``allan.csv``, ``allan.png``, ``filter.toml`` and, unless ``kalibr`` is
    False, the Kalibr ``imu.yaml`` (:mod:`kalcal.calibration.kalibr`) into ``out`` as one set; returns the
    summary as written (its ``files`` name where the files are once the set is in place)."""
    with run_outputs(out, "noise", names=output_names(kalibr), protect=inputs_of(run)) as staging:
        return _write_noise(run, staging, kalibr)


def _write_noise(run: NoiseRun, out: Path, kalibr: bool) -> dict[str, Any]:
    out = Path(out)
    paths = {
        "summary": out / "summary.json",
        "allan": out / "allan.csv",
        "plot": out / "allan.png",
        "filter": out / "filter.toml",
    }
    out.mkdir(parents=True, exist_ok=True)
    from kalcal.plots.allan import plot_allan

    plot_allan(run.identification, paths["plot"], title=run.title)
    run.allan.to_csv(paths["allan"], index=False)
    paths["filter"].write_text(run.filter_text)
    if kalibr:
        from kalcal.calibration.kalibr import kalibr_yaml

        paths["kalibr"] = out / KALIBR_NAME
        paths["kalibr"].write_text(kalibr_yaml(run.identification))
    summary = dict(run.summary)
    warnings = summary.pop("warnings")
    summary["files"] = {name: str(final_path(path)) for name, path in paths.items()}
    summary["warnings"] = warnings
    write_json(paths["summary"], summary)
    return summary


def compute_noise(
    imu_path: str | Path | pd.DataFrame,
    *,
    imu_columns: str | None = None,
    confidence: float = 0.95,
    strict: bool = False,
) -> NoiseRun:
    """Identify the noise of a static accelerometer log (time [s], accel [m/s^2]; CSV, Parquet or a
    DataFrame), in memory.

    :func:`save_noise` writes ``summary.json``, ``allan.csv`` (tau [s], adev and its bounds [m/s^2], edf,
    noise type), ``allan.png`` and ``filter.toml``. The log must be evenly sampled (steps
    within 1% of the median step), at a plausible accelerometer rate, with every sample within the physical
    limit (:mod:`kalcal.calibration.plausibility`). Columns are mapped with ``"time=t,accel=ax"``. A log that
    does not look static (:func:`~kalcal.calibration.motion.motion_warnings`) is flagged in the summary's
    ``warnings`` (``{"code", "message"}`` each, empty when none) and at the top of ``filter.toml``; with
    ``strict`` it is refused (DataError) before anything is written.
    """
    imu_map = parse_column_map(imu_columns, IMU_ROLES, "--imu-columns")
    frame = read_table(imu_path, "imu")
    source, imu_path = imu_path, source_name(imu_path, "imu")
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

    settings = filter_settings(result)
    curve = result.curve
    allan = pd.DataFrame(
        {
            "tau": curve.tau,
            "adev": curve.adev,
            "adev_low": curve.low,
            "adev_high": curve.high,
            "edf": curve.edf,
            "alpha": curve.alpha,
            "alpha_identified": curve.alpha_identified,
            "terms": curve.terms,
        }
    )
    flagged = "".join(f"# WARNING: {w.message}\n" for w in warnings)
    filter_text = flagged + filter_toml(result, settings, str(imu_path))
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
        "per_sample": per_sample_settings(result, settings),
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
        "warnings": [warning.as_dict() for warning in warnings],
    }
    run = NoiseRun(result, summary, filter_text, allan, f"kalcal noise: {Path(imu_path).name}")
    return run if isinstance(source, pd.DataFrame) else mark_inputs(run, source)  # a save never removes the log
