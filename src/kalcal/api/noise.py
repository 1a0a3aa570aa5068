"""``kalcal.noise``: accelerometer noise identified from a static log, returned as a NoiseResult."""

from __future__ import annotations

from pathlib import Path

from kalcal.api.results import NoiseResult


def noise(
    imu=None,
    *,
    imu_columns: str | None = None,
    confidence: float = 0.95,
    strict: bool = False,
    out: str | Path | None = None,
    kalibr: bool = True,
) -> NoiseResult:
    """Identify accelerometer noise from a static log: Allan deviation, N, B, K and the [filter] settings.

    Parameters
    ----------
    imu : DataFrame or path
        The static log: time [s], accel [m/s^2] (CSV, Parquet or a DataFrame).
    imu_columns : str, optional
        Map roles to columns, ``"time=t,accel=ax"``.
    confidence : float
        Level of the intervals (0.95).
    strict : bool
        Refuse (DataError) a log that does not look static.
    out : path, optional
        Also write the files there, as ``kalcal noise --out`` (the folder is checked first), the Kalibr
        ``imu.yaml`` among them unless ``kalibr`` is False.

    Returns
    -------
    NoiseResult
    """
    from kalcal.errors import KalcalError

    if imu is None:
        raise KalcalError("--imu: required (a static accelerometer log: time [s], accel [m/s^2])")
    from kalcal.jobs.noise import compute_noise, output_names, save_noise

    if out is None:
        return NoiseResult.from_run(compute_noise(imu, imu_columns=imu_columns, confidence=confidence, strict=strict))
    from kalcal.io.outputs import run_outputs

    protect = [imu] if isinstance(imu, (str, Path)) else []
    with run_outputs(out, "noise", names=output_names(kalibr), protect=protect) as staging:
        run = compute_noise(imu, imu_columns=imu_columns, confidence=confidence, strict=strict)
        summary = save_noise(run, staging, kalibr=kalibr)
    return NoiseResult.from_run(run, summary["files"])
