"""``kalcal.noise``: accelerometer noise identified from a static log, returned as a NoiseResult."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from kalcal.results.noise import NoiseResult


def noise(
    imu=None,
    *,
    imu_columns: str | None = None,
    confidence: float = 0.95,
    strict: bool = False,
    out: str | Path | None = None,
    kalibr: bool = True,
    topic: str | None = None,
    axis: str | None = None,
) -> NoiseResult:
    """Identify accelerometer noise from a static log: Allan deviation, N, B, K and the [filter] settings.

    Parameters
    ----------
    imu : DataFrame or path
        The static log: time [s], accel [m/s^2] (CSV, also .csv.gz/.bz2/.xz/.zst, Parquet or a DataFrame),
        or a ROS 1/2 bag's ``sensor_msgs/msg/Imu`` topic or a PX4 ULog's ``sensor_combined``, read as
        three axes (:func:`kalcal.calibration.noise_run.compute_noise`).
    imu_columns : str, optional
        Map roles to columns, ``"time=t,accel=ax"``.
    confidence : float
        Level of the intervals (0.95).
    strict : bool
        Refuse (DataError) a log that does not look static.
    out : path, optional
        Also write the files there, as ``kalcal noise --out`` (the folder is checked first), the Kalibr
        ``imu.yaml`` among them unless ``kalibr`` is False.
    topic : str, optional
        A bag's topic (default: its only ``sensor_msgs/msg/Imu`` topic) or a ULog's (``sensor_combined``).
    axis : {"x", "y", "z"}, optional
        Of a three-axis log, the axis whose ``[filter]`` settings are written (filter.toml) and whose
        parameters the result's attributes hold; every axis is in ``result.axes`` either way.

    Returns
    -------
    NoiseResult
    """
    from kalcal.errors import KalcalError

    if imu is None:
        raise KalcalError("--imu: required (a static accelerometer log: time [s], accel [m/s^2])")
    from kalcal.calibration.noise_run import compute_noise, output_names, save_noise

    if out is None:
        return compute_noise(imu, imu_columns=imu_columns, confidence=confidence, strict=strict, topic=topic, axis=axis)
    from kalcal.io.outputs import run_outputs

    protect = [imu] if isinstance(imu, (str, Path)) else []
    with run_outputs(out, "noise", names=output_names(kalibr), protect=protect) as staging:
        run = compute_noise(imu, imu_columns=imu_columns, confidence=confidence, strict=strict, topic=topic, axis=axis)
        summary = save_noise(run, staging, kalibr=kalibr)
    from kalcal.io.outputs import inputs_of, mark_inputs

    # the result as saved, still knowing the log it was read from (a later save never removes it)
    return mark_inputs(dataclasses.replace(run, paths=summary["files"]), *inputs_of(run))
