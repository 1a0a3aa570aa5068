"""scale-bias's stability test: its filter on K runs of consecutive samples of equal count.

Each window starts from theta's prior mean with a diffuse covariance (``filter.scale_error_std`` and
``filter.bias_std`` widened so that each theta's prior std is at least
:data:`~kalcal.calibration.windows.DIFFUSE` sqrt(K) times the whole log's final sigma), so that no window
inherits another's posterior. The rest of the filter is the whole run's.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from kalcal.calibration.stability import Stability, Window, compare_windows, untested
from kalcal.calibration.windows import DIFFUSE, check_windows
from kalcal.errors import DataError
from kalcal.scenarios.scale_bias.calibration import ScaleBiasCalibration, calibrate_scale_bias
from kalcal.scenarios.scale_bias.settings import STATE_NAMES, ScaleBiasScenario

__all__ = ["scale_bias_stability"]


def scale_bias_stability(
    scenario: ScaleBiasScenario,
    whole: ScaleBiasCalibration,
    time: np.ndarray,
    reference: np.ndarray,
    sensor: np.ndarray,
    windows: int = 2,
    **options,
) -> Stability:
    """The stability of theta = [theta1, theta2] of a scale-bias log across ``windows`` runs of samples.

    ``whole`` is the calibration of the whole log; ``options`` (``source``, ``columns``) those given to
    :func:`~kalcal.scenarios.scale_bias.calibration.calibrate_scale_bias` for it.
    """
    count = check_windows(windows)
    units = scenario.state_units
    q = scenario.filter_settings.parameter_drift_std
    model = "random walk" if q > 0 else "constant"
    prior = "each window from theta's prior mean with a diffuse covariance"
    if count == 1:
        return untested(STATE_NAMES, units, (), model, prior, "one window (--windows 1)")
    f = scenario.filter_settings
    gain = 1.0 - f.scale_error
    widths = DIFFUSE * np.sqrt(count) * whole.std[-1]
    widened = dataclasses.replace(
        scenario.filter,
        scale_error_std=max(f.scale_error_std, float(widths[0]) * gain**2),
        bias_std=max(f.bias_std, float(widths[1]) * gain),
    )
    window_scenario = dataclasses.replace(scenario, filter=widened)
    time, reference, sensor = (np.asarray(a, float) for a in (time, reference, sensor))
    found: list[Window] = []
    ends = []
    for i, rows in enumerate(np.array_split(np.arange(time.size), count)):
        where = f"window {i + 1} of {count}"
        if rows.size < 2:
            return untested(STATE_NAMES, units, found, model, prior, f"{where} has {rows.size} sample(s), fewer than 2")
        try:
            result = calibrate_scale_bias(window_scenario, time[rows], reference[rows], sensor[rows], **options)
        except DataError as exc:
            return untested(STATE_NAMES, units, found, model, prior, f"{where} (t {time[rows[0]]:.6g} to {time[rows[-1]]:.6g} s): {exc}")
        found.append(Window(float(time[rows[0]]), float(time[rows[-1]]), result.samples_used,
                            result.theta[-1].copy(), result.covariance[-1].copy()))  # fmt: skip
        ends.append(rows[-1])
    drift = None
    if model != "constant":
        # Q per sample: between two windows' last samples the walk adds (samples between) Q
        drift = np.diff(ends)[:, None, None] * scenario.filter_process_noise()[None]
    return compare_windows(found, STATE_NAMES, units, model=model, prior=prior, drift=drift)
