"""``kalcal fit accel-gps``: read the accelerometer and GPS logs and fit the filter's noise settings, in memory."""

from __future__ import annotations

from typing import Any

import numpy as np

from kalcal.errors import KalcalError
from kalcal.fitting.result import FitResult
from kalcal.fitting.run import KALIBR_NAME, OUTPUT_NAMES as FIT_NAMES, filter_toml, for_command
from kalcal.io.logs import is_frame, parse_column_map
from kalcal.io.outputs import mark_inputs
from kalcal.montecarlo.problem import MAX_UPDATES
from kalcal.scenarios.accel_gps.calibrate import GPS_ROLES, IMU_ROLES, _logs_of, read_accel_gps_logs, stated_rates

#: the files of an accel-gps fit: the Kalibr noise file too
OUTPUT_NAMES = (*FIT_NAMES, KALIBR_NAME)


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
    options=None,
) -> FitResult:
    """Fit an accel-gps log (files or DataFrames, as ``calibrate``); nothing is written (its ``save(out)``).

    ``prepare(scenario, imu_time, accel, gps_time, gps_position, gps_velocity, **options)`` builds the
    log-likelihood (default: :func:`kalcal.scenarios.accel_gps.log.prepare_accel_gps_log`, O(fixes) per
    evaluation; :func:`kalcal.scenarios.accel_gps.fit_reference.prepare_reference_accel_gps_log` is its oracle).
    ``options`` (:class:`~kalcal.fitting.run.FitOptions`): its bootstrap, seed, threads and client.
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
    # calibrate's reading, on one time origin: with velocity-only fixes no position column (gps["position"] is None)
    imu_name, imu, gps_name, gps = read_accel_gps_logs(scenario, imu_path, gps_path, imu_map, gps_map)
    has = {role: role in gps for role in ("position_std", "velocity_std")}
    positions = 0 in scenario.fix_states
    free = default_free(has["position_std"], has["velocity_std"], positions=positions) if not free else list(free)
    check_free(free, position_std=has["position_std"], velocity_std=has["velocity_std"], positions=positions)
    log = prepare(
        scenario, imu["time"], imu["accel"], gps["time"], gps["position"], gps["velocity"],
        position_std=gps.get("position_std"), velocity_std=gps.get("velocity_std"), init=init, prior="auto",
        source=str(gps_name), imu_source=str(imu_name), **stated_rates(scenario),
        columns={**{role: gps_map[role] for role in GPS_ROLES}, "imu_time": imu_map["time"], "accel": imu_map["accel"]},
    )
    medians = {role: float(np.nanmedian(gps[role])) for role in ("position_std", "velocity_std") if role in gps}
    result = fit_accel_gps(
        log, scenario, free, profile=profile, gate=gate, confidence=confidence,
        rates=log_rates(imu["time"], gps["time"]), std_medians=medians, max_updates=MAX_UPDATES, options=options,
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
    from kalcal.calibration.kalibr import fit_kalibr_yaml

    kalibr = fit_kalibr_yaml(result, str(imu_name), result.extra["per_sample"]["rate"])
    from kalcal.scenarios.accel_gps.fit import LINEAR

    inputs = {"imu": imu_name, "gps": gps_name, "init": init}
    run = for_command(result, "fit accel-gps", inputs, free, filter_toml(result, header), kalibr, tuple(LINEAR))
    files = [p for p in sources if not is_frame(p)]
    return mark_inputs(run, *files)


def fit_logs(scenario, logs: dict[str, Any], options) -> FitResult:
    """:meth:`AccelGpsScenario.fit`: the logs checked, then :func:`compute_accel_gps_fit`."""
    imu, gps = _logs_of(scenario, logs)
    if options.reference != "reference" or options.sensor != "sensor":
        raise KalcalError("--reference/--sensor: not used by accel-gps (scale-bias only)")
    return compute_accel_gps_fit(scenario, imu, gps, free=options.free, imu_columns=options.imu_columns,
                                 gps_columns=options.gps_columns, init=options.init, profile=options.profile,
                                 gate=options.gate, confidence=options.confidence, options=options)
