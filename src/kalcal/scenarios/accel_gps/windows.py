"""accel-gps's stability test: its filter on K windows of one log, each from its own first fix.

Windows are K spans of equal length over the fixes' times (within the accelerometer log), each with the
accelerometer samples that cover it. Each window starts at its own first fix, as ``--init first-fix``,
whatever ``--init`` the whole run used: position and velocity from that fix with the GPS noise as their
covariance. The bias (and the scale factor) get a diffuse prior, mean 0 and std
:data:`~kalcal.calibration.windows.DIFFUSE` sqrt(K) times the whole log's final sigma. A Gauss-Markov bias
keeps the model's stationary std ``bias_std`` as its prior (the model says that is the bias's spread at any
time, and its dynamics depend on it). The rest of the filter (noise, drift, update form) is the whole run's.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from kalcal.calibration.stability import Stability, Window, compare_windows, time_windows, untested
from kalcal.calibration.windows import DIFFUSE, check_windows
from kalcal.errors import DataError
from kalcal.scenarios.accel_gps.discretization import bias_discretization
from kalcal.scenarios.accel_gps.result import AccelGpsCalibration
from kalcal.scenarios.accel_gps.settings import AccelGpsScenario

__all__ = ["accel_gps_stability"]


def _accel_gps_model(scenario: AccelGpsScenario) -> str:
    f = scenario.filter_settings
    if f.bias_correlation_time > 0:
        return "Gauss-Markov"
    return "random walk" if f.bias_walk_std > 0 else "constant"


def accel_gps_stability(
    scenario: AccelGpsScenario,
    whole: AccelGpsCalibration,
    imu_time: np.ndarray,
    accel: np.ndarray,
    gps_time: np.ndarray,
    gps_position: np.ndarray,
    gps_velocity: np.ndarray,
    windows: int = 2,
    *,
    position_std: np.ndarray | None = None,
    velocity_std: np.ndarray | None = None,
    **options,
) -> Stability:
    """The stability of the bias (and scale) of an accel-gps log across ``windows`` windows.

    ``whole`` is the calibration of the whole log (its final sigma sets the diffuse priors); the logs
    and ``options`` (``form``, ``max_imu_gap``, ``source``, ...) are those given to
    :func:`~kalcal.scenarios.accel_gps.calibration.calibrate_accel_gps` for it; ``init`` is always "first-fix".
    A window the filter cannot run on (too few fixes) leaves the test not run, its sentence saying why.
    """
    # the filter (and numba, under it) loads when a stability test runs, as calibrate.py loads it
    from kalcal.scenarios.accel_gps.calibration import calibrate_accel_gps

    count = check_windows(windows)
    # the noise per sample at the log's own rate, as the whole log's calibration took it
    scenario = scenario.at_rate(1.0 / float(np.median(np.diff(np.asarray(imu_time, dtype=float)))))
    names = ("bias", "scale") if scenario.has_scale else ("bias",)
    units = ("m/s^2", "1")[: len(names)]
    model = _accel_gps_model(scenario)
    widths = DIFFUSE * np.sqrt(count) * whole.std[-1, 2 : 2 + len(names)]
    changes = {"scale_std": float(widths[1])} if scenario.has_scale else {}
    if model == "Gauss-Markov":
        prior = "each window from its own first fix; the bias's stationary std as its prior"
    else:
        prior = "each window from its own first fix; the bias diffuse"
        changes["bias_std"] = float(widths[0])
    if scenario.has_scale:
        prior += ", the scale factor diffuse"
    if count == 1:
        return untested(names, units, (), model, prior, "one window (--windows 1)")
    window_scenario = dataclasses.replace(scenario, filter=dataclasses.replace(scenario.filter, **changes))
    imu_time, gps_time = np.asarray(imu_time, float), np.asarray(gps_time, float)
    finite = gps_time[np.isfinite(gps_time)]
    start, end = max(finite.min(), imu_time[0]), min(finite.max(), imu_time[-1])
    arrays = [np.asarray(a, float) if a is not None else None for a in (gps_position, gps_velocity, position_std, velocity_std)]
    found: list[Window] = []
    for i, rows in enumerate(time_windows(gps_time, count, start, end)):
        where = f"window {i + 1} of {count}"
        if rows.size < 3:
            return untested(names, units, found, model, prior, f"{where} has {rows.size} fix(es), fewer than 3")
        first, last = gps_time[rows[0]], gps_time[rows[-1]]
        lo = max(int(np.searchsorted(imu_time, first, side="right")) - 2, 0)
        hi = min(int(np.searchsorted(imu_time, last, side="left")) + 2, imu_time.size)
        position, velocity, p_std, v_std = (None if a is None else a[rows] for a in arrays)
        try:
            result = calibrate_accel_gps(
                window_scenario, imu_time[lo:hi], np.asarray(accel, float)[lo:hi], gps_time[rows], position, velocity,
                position_std=p_std, velocity_std=v_std, init="first-fix", stop_on_gap=False, **options,
            )  # fmt: skip
        except (DataError, np.linalg.LinAlgError) as exc:
            return untested(names, units, found, model, prior, f"{where} (t {first:.6g} to {last:.6g} s): {exc}")
        d = len(names)
        found.append(
            Window(float(result.start_time), float(result.time[-1]), int(result.time.size) + 1,
                   result.error_state[-1, 2 : 2 + d].copy(), result.covariance[-1, 2 : 2 + d, 2 : 2 + d].copy())
        )  # fmt: skip
    transitions = drift = None
    if model != "constant":
        period = float(np.median(np.diff(imu_time)))
        spans = np.diff([w.end for w in found])
        decay, variance = bias_discretization(scenario.filter_settings, spans, period)
        d = len(names)
        transitions = np.broadcast_to(np.eye(d), (count - 1, d, d)).copy()
        drift = np.zeros((count - 1, d, d))
        transitions[:, 0, 0], drift[:, 0, 0] = decay, variance
    return compare_windows(found, names, units, model=model, prior=prior, transitions=transitions, drift=drift)
