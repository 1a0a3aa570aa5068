"""``kalcal noise``: a static accelerometer log's noise identified in memory, then written as one set.

It writes the summary, the Allan curve and plot, the matching ``[filter]`` settings (rate-free densities,
converted by ``calibrate`` at each log's own rate) and Kalibr's imu.yaml.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pandas as pd

from kalcal.calibration.allan import regular_rate
from kalcal.calibration.noise import NoiseIdentification, identify_noise
from kalcal.calibration.plausibility import CalibrationWarning, check_limit, check_rate
from kalcal.errors import DataError
from kalcal.io.logs import numeric_columns, parse_column_map, read_table, require_increasing, source_name, topic_of
from kalcal.io.outputs import final_path, inputs_of, mark_inputs, run_outputs
from kalcal.io.results import write_json
from kalcal.results.noise import NoiseResult
from kalcal.scenarios import NoiseFilter, noise_filter

IMU_ROLES = ("time", "accel")
#: the files of ``kalcal noise`` (and :data:`KALIBR_NAME` unless it is left out)
OUTPUT_NAMES = ("summary.json", "allan.csv", "allan.png", "filter.toml")
#: the Kalibr noise file, written beside filter.toml by default
KALIBR_NAME = "imu.yaml"


def output_names(kalibr: bool = True) -> tuple[str, ...]:
    """The files of one ``kalcal noise`` run: :data:`OUTPUT_NAMES`, with ``kalibr`` :data:`KALIBR_NAME` too."""
    return (*OUTPUT_NAMES, KALIBR_NAME) if kalibr else OUTPUT_NAMES


def save_noise(run: NoiseResult, out: str | Path, *, kalibr: bool = True) -> dict[str, Any]:
    """Write ``summary.json``, ``allan.csv``, ``allan.png``, ``filter.toml`` (where the run has one) and,
    unless ``kalibr`` is False, the Kalibr ``imu.yaml`` (:mod:`kalcal.calibration.kalibr`) into ``out`` as
    one set; returns the summary as written (its ``files`` name where the files are once the set is in
    place)."""
    with run_outputs(out, "noise", names=output_names(kalibr), protect=inputs_of(run)) as staging:
        return _write_noise(run, staging, kalibr)


def _write_noise(run: NoiseResult, out: Path, kalibr: bool) -> dict[str, Any]:
    out = Path(out)
    paths = {
        "summary": out / "summary.json",
        "allan": out / "allan.csv",
        "plot": out / "allan.png",
        "filter": out / "filter.toml",
    }
    out.mkdir(parents=True, exist_ok=True)
    from kalcal.plots.allan import plot_allan, plot_allan_axes

    if run.axes:
        plot_allan_axes(run.axes, paths["plot"], title=run.title, selected=run.raw_summary.get("axis"))
    else:
        plot_allan(run.identification, paths["plot"], title=run.title)
    run.allan.to_csv(paths["allan"], index=False)
    if run.filter_text is None:
        del paths["filter"]
    else:
        paths["filter"].write_text(run.filter_text)
    if kalibr:
        from kalcal.calibration.kalibr import axes_kalibr_yaml, kalibr_yaml

        paths["kalibr"] = out / KALIBR_NAME
        rostopic = run.topic or "/imu0"
        text = axes_kalibr_yaml(run.axes, rostopic) if run.axes else kalibr_yaml(run.identification, rostopic)
        paths["kalibr"].write_text(text)
    summary = dict(run.raw_summary)
    warnings = summary.pop("warnings")
    summary["files"] = {name: str(final_path(path)) for name, path in paths.items()}
    summary["warnings"] = warnings
    write_json(paths["summary"], summary)
    return summary


#: the axes of a three-axis accelerometer
AXES = ("x", "y", "z")


def imu_columns_for(path, imu_columns: str | None, topic: str | None, axis: str | None):
    """The columns ``kalcal noise`` reads: ``({role: column}, axes, topic)``.

    A CSV, Parquet or DataFrame log has one accelerometer column (``time=t,accel=ax``; roles
    :data:`IMU_ROLES`). A ROS bag or ULog has three axes unless ``accel=TOPIC.FIELD`` names one: the
    bag's ``sensor_msgs/msg/Imu`` topic (``--topic``, else its only one) ``TOPIC.linear_acceleration.x``
    ..., the ULog's ``sensor_combined.accelerometer_m_s2[0]`` .... ``axes`` is :data:`AXES` for three
    axes (the roles are then ``time``, ``x``, ``y``, ``z``), else None.
    """
    from kalcal.io.logs import TOPIC_FORMATS, is_frame, log_format

    mapping = parse_column_map(imu_columns, IMU_ROLES, "--imu-columns")
    kind = None if is_frame(path) else log_format(path)
    if axis is not None and axis not in AXES:
        raise DataError(f"--axis {axis!r}: expected one of {', '.join(AXES)}")
    three = kind in TOPIC_FORMATS and mapping["accel"] == "accel"
    if not three:
        if axis is not None:
            raise DataError(
                f"--axis {axis}: selects one of a ROS bag's or ULog's three accelerometer axes; "
                f"{source_name(path, 'imu')} is read as one accel column"
            )
        if kind in TOPIC_FORMATS and topic is not None:
            named = topic_of(mapping, path)
            if named is not None and named != topic:
                raise DataError(f"{path}: --topic {topic} but --imu-columns names topic {named}")
        return mapping, None, topic
    if kind == "rosbag":
        from kalcal.io.rosbag import IMU_TYPE, bag_topics, imu_topic

        topic = topic or imu_topic(path)
        topics = bag_topics(path)
        if topic in topics and topics[topic][0] != IMU_TYPE:
            raise DataError(f"{path}: topic {topic} holds {topics[topic][0]} messages, expected {IMU_TYPE}")
        fields = [f"{topic}.linear_acceleration.{a}" for a in AXES]
    else:
        from kalcal.io.ulog import IMU_FIELDS, IMU_TOPIC

        topic = topic or IMU_TOPIC
        fields = [f"{topic}.{field}" for field in IMU_FIELDS]
    return {"time": mapping["time"], **dict(zip(AXES, fields))}, AXES, topic


def log_format_of(source) -> str | None:
    """The format of a log (:func:`kalcal.io.logs.log_format`), None for a DataFrame."""
    from kalcal.io.logs import is_frame, log_format

    return None if is_frame(source) else log_format(source)


def _identify(accel, rate, confidence, duration, source, column) -> NoiseIdentification:
    try:
        return identify_noise(accel, rate, confidence, duration=duration)
    except DataError as exc:
        raise DataError(f"{source}: column {column!r}: {exc}") from None


def _allan_frame(curve) -> pd.DataFrame:
    return pd.DataFrame(
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


def _axis_summary(result: NoiseIdentification, written: NoiseFilter) -> dict[str, Any]:
    """The keys of summary.json that describe one accelerometer column's identification."""
    curve = result.curve
    return {
        "mean": {"value": result.mean, "unit": "m/s^2", "note": "constant bias plus any gravity component"},
        "std": {"value": result.std, "unit": "m/s^2", "note": "of the samples about their mean"},
        **{parameter.name: parameter.as_dict() for parameter in result.parameters},
        "filter": written.settings,
        "per_sample": written.per_sample,
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
    }


def compute_noise(
    imu_path: str | Path | pd.DataFrame,
    *,
    imu_columns: str | None = None,
    confidence: float = 0.95,
    strict: bool = False,
    topic: str | None = None,
    axis: str | None = None,
) -> NoiseResult:
    """Identify the noise of a static accelerometer log (time [s], accel [m/s^2]; CSV, Parquet, a
    DataFrame, a ROS bag's ``sensor_msgs/msg/Imu`` topic or a ULog's ``sensor_combined``), in memory: the
    :class:`~kalcal.results.noise.NoiseResult` it makes.

    :func:`save_noise` writes ``summary.json``, ``allan.csv`` (tau [s], adev and its bounds [m/s^2], edf,
    noise type), ``allan.png``, ``filter.toml`` and Kalibr's ``imu.yaml``. The log must be evenly sampled
    (steps within 1% of the median step), at a plausible accelerometer rate, with every sample within the
    physical limit (:mod:`kalcal.calibration.plausibility`). Columns are mapped with ``"time=t,accel=ax"``.
    A log that does not look static (:func:`~kalcal.calibration.motion.motion_warnings`) is flagged in the
    summary's ``warnings`` (``{"code", "message"}`` each, empty when none) and at the top of
    ``filter.toml``; with ``strict`` it is refused (DataError) before anything is written.

    A bag or ULog is read as three axes (:func:`imu_columns_for`; ``accel=TOPIC.FIELD`` reads one column
    as a CSV's): summary.json's ``axes`` holds each axis's identification and Allan curve, imu.yaml the
    largest of the three densities, and filter.toml is written for the axis ``axis`` (``"x"``, ``"y"``,
    ``"z"``) selects, none without it (the filter is of one axis).
    """
    imu_map, axes, topic = imu_columns_for(imu_path, imu_columns, topic, axis)
    frame = read_table(imu_path, "imu", topic=topic, columns=imu_map)
    source, imu_path = imu_path, source_name(imu_path, "imu", frame)
    imu = numeric_columns(frame, imu_path, imu_map)
    time = imu["time"]
    require_increasing(time, imu_path, imu_map["time"])
    rate = regular_rate(time, str(imu_path), imu_map["time"])
    check_rate(time, "accelerometer", str(imu_path), imu_map["time"])
    check_limit(time, "time", str(imu_path), imu_map["time"])
    roles = axes or ("accel",)
    for role in roles:  # "row N, column 'accel'" as in calibrate
        check_limit(imu[role], "accel", str(imu_path), imu_map[role])
    duration = float(time[-1] - time[0])
    results = {role: _identify(imu[role], rate, confidence, duration, imu_path, imu_map[role]) for role in roles}
    warnings = [
        CalibrationWarning(w.code, f"{imu_path}" + (f": column {imu_map[role]!r}" if axes else "") + f": {w.message}")
        for role, result in results.items() for w in result.warnings
    ]
    if strict and warnings:
        raise DataError(f"{warnings[0].message} (--strict: refused, nothing written)")
    flagged = "".join(f"# WARNING: {w.message}\n" for w in warnings)
    name = Path(str(source)).name if "source" in frame.attrs else Path(imu_path).name
    title = f"kalcal noise: {name}" + (f" {topic_of(imu_map) or topic}" if "source" in frame.attrs else "")
    # Kalibr's rostopic is a ROS topic: the bag's; a ULog's or a table's keeps Kalibr's default
    rostopic = (topic or topic_of(imu_map)) if log_format_of(source) == "rosbag" else None
    if axes is None:
        result = results["accel"]
        written = noise_filter(result, str(imu_path))
        axis_summary = _axis_summary(result, written)
        summary = {
            "imu": str(imu_path),
            "columns": imu_map,
            "samples": result.samples,
            "rate": {"value": result.rate, "unit": "Hz", "note": "median sample rate"},
            "sample_period": {"value": result.sample_period, "unit": "s"},
            "duration": {"value": result.duration, "unit": "s"},
            "mean": axis_summary.pop("mean"),
            "std": axis_summary.pop("std"),
            "confidence": confidence,
            **axis_summary,
            "warnings": [warning.as_dict() for warning in warnings],
        }
        filter_text = flagged + written.toml
        run = NoiseResult(result, summary, filter_text, _allan_frame(result.curve), title, topic=rostopic)
    else:
        first = results[axes[0]]
        blocks, written = {}, {}
        for role, result in results.items():
            written[role] = noise_filter(result, f"{imu_path}, axis {role} ({imu_map[role]})")
            blocks[role] = {"column": imu_map[role], **_axis_summary(result, written[role])}
        selected = results[axis] if axis else None
        notes = [f"axis {role}: {note}" for role, block in blocks.items() for note in block["notes"]]
        if axis is None:
            notes.append("filter.toml not written: the filter is of one axis, select it with --axis x, y or z")
            filter_text = None
        else:
            filter_text = flagged + written[axis].toml
        summary = {
            "imu": str(imu_path),
            "topic": topic,
            "time": frame.attrs.get("time", ""),
            "columns": imu_map,
            "samples": first.samples,
            "rate": {"value": first.rate, "unit": "Hz", "note": "median sample rate"},
            "sample_period": {"value": first.sample_period, "unit": "s"},
            "duration": {"value": first.duration, "unit": "s"},
            "confidence": confidence,
            "axis": axis,
            "filter": {} if axis is None else blocks[axis]["filter"],
            "axes": blocks,
            "notes": notes,
            "warnings": [warning.as_dict() for warning in warnings],
        }
        allan = pd.concat([_allan_frame(r.curve).assign(axis=role) for role, r in results.items()], ignore_index=True)
        allan = allan[["axis", *[c for c in allan.columns if c != "axis"]]]
        run = NoiseResult(selected, summary, filter_text, allan, title, axes=results, topic=rostopic)
    return run if isinstance(source, pd.DataFrame) else mark_inputs(run, source)  # a save never removes the log
