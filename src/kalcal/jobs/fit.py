"""``kalcal fit``: read a log, fit the filter's noise settings in memory, write its files as one set.

The files are fit.json, filter.toml and fit.png, and for accel-gps Kalibr's imu.yaml."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from kalcal.errors import DataError, KalcalError
from kalcal.fitting.result import FitResult
from kalcal.io.logs import check_gnss_columns, is_frame, numeric_columns, parse_column_map, read_table, require_increasing, source_name
from kalcal.io.outputs import inputs_of, mark_inputs, run_outputs
from kalcal.io.results import write_json
from kalcal.jobs.calibrate import GPS_ROLES, IMU_ROLES, stated_rates
from kalcal.jobs.verify import MAX_UPDATES

#: the files of one fit
OUTPUT_NAMES = ("fit.json", "filter.toml", "fit.png")
#: ... and of an accel-gps fit: the Kalibr noise file too, as ``kalcal noise`` writes it
KALIBR_NAME = "imu.yaml"


def output_names(command: str) -> tuple[str, ...]:
    """The files of a ``command`` (``"fit accel-gps"``, ``"fit scale-bias"``) run."""
    return (*OUTPUT_NAMES, KALIBR_NAME) if command == "fit accel-gps" else OUTPUT_NAMES


@dataclass(frozen=True)
class FitRun:
    """A fit computed in memory, nothing written yet.

    Attributes
    ----------
    command : str
        ``"fit accel-gps"`` or ``"fit scale-bias"``.
    result : FitResult
    document : dict
        fit.json's content.
    filter_text : str
        filter.toml, loadable by ``--config`` of calibrate and verify.
    kalibr_text : str or None
        accel-gps: imu.yaml, the fitted noise densities in Kalibr's form (:func:`kalcal.calibration.kalibr.fit_kalibr_yaml`).
    """

    command: str
    result: FitResult
    document: dict[str, Any]
    filter_text: str
    kalibr_text: str | None = None


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    return repr(float(value))


def filter_toml(result: FitResult, header: list[str]) -> str:
    """filter.toml: ``header`` as comments, then each section; a fitted key carries its interval as a
    comment above it, an unidentified one its note (the input value kept; a ridge's members: the fitted point)."""
    lines = [f"# {line}" for line in header]
    lines += [f"# {note}" for note in result.notes]
    used = set()
    for section, values in result.settings.items():
        lines += ["", f"[{section}]"]
        for key, value in values.items():
            # a comment keyed "section.key" belongs to that key, a bare key to [filter]'s
            for name in (f"{section}.{key}", key if section == "filter" else None):
                if name in result.comments:
                    lines.append(f"# {result.comments[name]}")
                    used.add(name)
            lines.append(f"{key} = {_toml_value(value)}")
    extra = [text for key, text in result.comments.items() if key not in used]
    if extra:
        lines += [""] + [f"# {text}" for text in extra]
    return "\n".join(lines) + "\n"


def _document(result: FitResult, command: str, sources: dict[str, str], free: list[str]) -> dict[str, Any]:
    return {**result.to_dict(), "command": command, "inputs": sources, "free": free, "settings": result.settings}


def compute_accel_gps_fit(
    scenario,
    imu_path,
    gps_path,
    *,
    free: list[str] | None = None,
    imu_columns: str | None = None,
    gps_columns: str | None = None,
    init: str = "first-fix",
    profile: bool = False,
    gate: float | None = None,
    confidence: float = 0.95,
    prepare=None,
) -> FitRun:
    """Fit an accel-gps log (files or DataFrames, as ``calibrate``); nothing is written (:func:`save_fit`).

    ``prepare(scenario, imu_time, accel, gps_time, gps_position, gps_velocity, **options)`` builds the
    log-likelihood (default: :func:`kalcal.scenarios.accel_gps.log.prepare_accel_gps_log`, O(fixes) per
    evaluation; :func:`kalcal.scenarios.accel_gps.fit_reference.prepare_reference_accel_gps_log` is its oracle).
    The log's prior is ``calibrate``'s ("auto": a diffuse bias unless ``filter.bias_std`` is given, with
    the conditional likelihood).
    """
    from kalcal.scenarios.accel_gps.fit import check_free, default_free, fit_accel_gps, log_rates

    if gate is not None and not 0.0 < gate < 1.0:
        raise KalcalError(f"--gate: expected a confidence in (0, 1), got {gate!r}")
    if prepare is None:
        from kalcal.scenarios.accel_gps.log import prepare_accel_gps_log as prepare
    imu_map = parse_column_map(imu_columns, IMU_ROLES, "--imu-columns")
    gps_map = parse_column_map(gps_columns, GPS_ROLES, "--gps-columns")
    sources = (imu_path, gps_path)
    imu_frame = read_table(imu_path, "imu", columns=imu_map)
    gps_frame = read_table(gps_path, "gps", columns={role: gps_map[role] for role in ("time", "position", "velocity")})
    imu_name, gps_name = source_name(imu_path, "imu", imu_frame), source_name(gps_path, "gps", gps_frame)
    check_gnss_columns(gps_frame, gps_name, gps_map)
    imu = numeric_columns(imu_frame, imu_name, imu_map)
    optional = [role for role in ("position_std", "velocity_std") if gps_map[role] in gps_frame.columns]
    gps = numeric_columns(
        gps_frame, gps_name, {role: gps_map[role] for role in ("time", "position", "velocity", *optional)},
        allow_nan=("position", "velocity", *optional),
    )
    require_increasing(imu["time"], imu_name, imu_map["time"])
    require_increasing(gps["time"], gps_name, gps_map["time"])
    has = {role: role in gps for role in ("position_std", "velocity_std")}
    free = default_free(has["position_std"], has["velocity_std"]) if not free else list(free)
    check_free(free, position_std=has["position_std"], velocity_std=has["velocity_std"])
    log = prepare(
        scenario, imu["time"], imu["accel"], gps["time"], gps["position"], gps["velocity"],
        position_std=gps.get("position_std"), velocity_std=gps.get("velocity_std"), init=init, prior="auto",
        source=str(gps_name), imu_source=str(imu_name), **stated_rates(scenario),
        columns={**{role: gps_map[role] for role in GPS_ROLES}, "imu_time": imu_map["time"], "accel": imu_map["accel"]},
    )
    medians = {role: float(np.nanmedian(gps[role])) for role in ("position_std", "velocity_std") if role in gps}
    result = fit_accel_gps(
        log, scenario, free, profile=profile, gate=gate, confidence=confidence,
        rates=log_rates(imu["time"], gps["time"]), std_medians=medians, max_updates=MAX_UPDATES,
    )
    header = [
        f"kalcal fit accel-gps: noise settings fitted by maximum likelihood to {imu_name} and {gps_name}",
        f"({result.fixes} fixes, log L = {result.loglik:.6g}, {result.interval_method} intervals).",
        "The noise is written as rate-free densities (calibrate converts them at each log's own rate; the per-sample",
        "values at this log's rate are in comments). `kalcal verify --config` on this file",
        "runs the fitted filter against these settings as the truth, over [scenario] duration and the scenario's",
        "motion, not the log's.",
    ]
    if gate is not None:  # the fit's settings hold for the fixes the gate left; a calibration must leave the same
        header.append(f"fitted with --gate {gate:g} ({len(result.rejected_fixes or [])} fixes rejected): calibrate with "
                      f"the same --gate {gate:g}")
    if not result.adequate:
        header.append(f"NOT ADEQUATE: {result.adequacy}")
    document = _document(result, "fit accel-gps", {"imu": imu_name, "gps": gps_name, "init": init}, free)
    from kalcal.calibration.kalibr import fit_kalibr_yaml

    kalibr = fit_kalibr_yaml(result, str(imu_name), result.extra["per_sample"]["rate"])
    run = FitRun("fit accel-gps", result, document, filter_toml(result, header), kalibr)
    files = [p for p in sources if not is_frame(p)]
    return mark_inputs(run, *files)


def compute_scale_bias_fit(
    scenario,
    data_path,
    *,
    free: list[str] | None = None,
    reference: str = "reference",
    sensor: str = "sensor",
    profile: bool = False,
    confidence: float = 0.95,
) -> FitRun:
    """Fit a scale-bias log (a reference and a sensor column, optionally ``time`` [s]); nothing is written."""
    from kalcal.scenarios.scale_bias.fit import fit_scale_bias

    frame = read_table(data_path, "data", columns=(reference, sensor))
    name = source_name(data_path, "data", frame)
    if reference == sensor:
        raise DataError(f"{name}: --reference and --sensor name the same column {reference!r}")
    columns = numeric_columns(frame, name, {"reference": reference, "sensor": sensor}, allow_nan=("reference", "sensor"))
    if "time" in frame.columns and "time" not in (reference, sensor):
        time = numeric_columns(frame, name, ("time",))["time"]
        require_increasing(time, name)
        rate = float(1.0 / np.median(np.diff(time))) if time.size > 1 else None
    else:
        time, rate = np.arange(1, len(frame) + 1) / scenario.scenario.rate, None
    if np.count_nonzero(np.isfinite(columns["reference"]) & np.isfinite(columns["sensor"])) < 3:
        raise DataError(f"{name}: needs at least three samples with both a reference and a sensor value")
    result = fit_scale_bias(scenario, time, columns["reference"], columns["sensor"], free=free, profile=profile,
                            confidence=confidence, rate=rate, max_updates=MAX_UPDATES)
    header = [
        f"kalcal fit scale-bias: noise settings fitted by maximum likelihood to {name}",
        f"({result.fixes} samples in the likelihood, log L = {result.loglik:.6g}, {result.interval_method} intervals).",
        "`kalcal verify scale-bias --config` on this file runs the fitted filter against these settings as the truth,",
        "over [scenario] duration and the scenario's excitation, not the log's.",
    ]
    if not result.adequate:
        header.append(f"NOT ADEQUATE: {result.adequacy}")
    document = _document(result, "fit scale-bias", {"data": name}, list(free or result.parameters))
    run = FitRun("fit scale-bias", result, document, filter_toml(result, header))
    return run if is_frame(data_path) else mark_inputs(run, data_path)


def save_fit(run: FitRun, out: str | Path) -> dict[str, Path]:
    """Write ``fit.json``, ``filter.toml``, ``fit.png`` and, for accel-gps, ``imu.yaml`` into ``out`` as one
    set (:mod:`kalcal.io.outputs`); returns the files by name (where they are once the set is in place)."""
    out = Path(out)
    names = output_names(run.command)
    with run_outputs(out, run.command, names=names, protect=inputs_of(run)) as staging:
        staging.mkdir(parents=True, exist_ok=True)
        from kalcal.fitting.mle import drop_of
        from kalcal.plots.fit import plot_fit

        linear = ()
        if run.command == "fit accel-gps":
            from kalcal.scenarios.accel_gps.fit import LINEAR as linear
        write_json(staging / "fit.json", run.document)
        (staging / "filter.toml").write_text(run.filter_text)
        if run.kalibr_text is not None:
            (staging / KALIBR_NAME).write_text(run.kalibr_text)
        plot_fit(run.result.curves, run.document["parameters"], staging / "fit.png",
                 method=run.result.interval_method, drop=drop_of(run.result.confidence), linear=tuple(linear))
    return {name: out / name for name in names}
