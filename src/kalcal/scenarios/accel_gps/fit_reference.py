"""The reference accel-gps log-likelihood: one whole calibration per evaluation (O(samples), slow, exact).

Each evaluation runs :func:`~kalcal.scenarios.accel_gps.calibration.calibrate_accel_gps` with the scenario's
filter settings replaced by the given values and sums the prediction-error decomposition of its
innovations, log L = -1/2 sum_k (log det S_k + r_k^T S_k^-1 r_k + p log 2 pi). It is the likelihood's
definition, which a faster evaluation over the same log is held to; the fit
(:mod:`kalcal.scenarios.accel_gps.fit`) takes either. With ``init="first-fix"`` the first fix starts the filter
and is not in the sum: the conditional likelihood of the other fixes given it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np

from kalcal.scenarios.accel_gps.calibration import AccelGpsCalibration, calibrate_accel_gps
from kalcal.scenarios.accel_gps.evaluation import UNITS
from kalcal.core.likelihood import innovation_loglik
from kalcal.errors import KalcalError
from kalcal.scenarios.accel_gps.settings import AccelGpsFilter, AccelGpsScenario

MULTIPLIERS = {"log.position_std_multiplier": "position_std", "log.velocity_std_multiplier": "velocity_std"}


def loglik_of(calibration: AccelGpsCalibration) -> float:
    """-1/2 sum_k (log det S_k + r_k^T S_k^-1 r_k + p log 2 pi) over a calibration's fixes used: the gate's
    rejections and the first ``calibration.skip`` fixes (a diffuse prior's) left out."""
    rejected = np.zeros(calibration.time.size, dtype=bool) if calibration.rejected is None else calibration.rejected
    residual = np.where(rejected[:, None], np.nan, calibration.residual)
    return innovation_loglik(residual, calibration.innovation_cov, skip=calibration.skip)


class ReferenceAccelGpsLog:
    """One accel-gps log and the filter to fit to it; every evaluation is a whole calibration.

    Parameters
    ----------
    scenario : AccelGpsScenario
        The settings that are not free, and the starts of those that are.
    imu_time, accel, gps_time, gps_position, gps_velocity, position_std, velocity_std
        As :func:`~kalcal.scenarios.accel_gps.calibration.calibrate_accel_gps` (s, m/s^2, m, m/s).
    **options
        The rest of calibrate_accel_gps's keywords (``init``, ``source``, ``columns``, rates, ...).
    """

    def __init__(self, scenario: AccelGpsScenario, imu_time, accel, gps_time, gps_position, gps_velocity, *,
                 position_std=None, velocity_std=None, **options: Any):
        self.scenario = scenario
        self.arrays = (imu_time, accel, gps_time, gps_position, gps_velocity)
        self.columns = {"position_std": position_std, "velocity_std": velocity_std}
        self.options = options
        self.fixes = int(self.calibrate({}).time.size)  # the log's checks run here, once

    def settings_value(self, key: str) -> float:
        """The input value of ``key`` (a multiplier's is 1)."""
        if key in MULTIPLIERS:
            return 1.0
        section, _, name = key.partition(".")
        if section != "filter" or not hasattr(self.scenario.filter_settings, name):
            raise KalcalError(f"--free: {key} is not a setting of the accel-gps filter")
        return float(getattr(self.scenario.filter_settings, name))

    def unit(self, key: str) -> str:
        return UNITS.get(key, "")

    def _scenario(self, values: Mapping[str, float]) -> AccelGpsScenario:
        changes = {key.partition(".")[2]: float(v) for key, v in values.items() if key.startswith("filter.")}
        accepted = {f.name for f in dataclasses.fields(AccelGpsFilter)}
        refused = sorted(set(changes) - accepted)
        if refused:
            raise KalcalError(f"--free: filter.{refused[0]} is not a setting of this build's accel-gps filter")
        return dataclasses.replace(self.scenario, filter=dataclasses.replace(self.scenario.filter, **changes))

    def calibrate(self, values: Mapping[str, float], *, gate: float | None = None) -> AccelGpsCalibration:
        """The calibration with ``values`` (``{"filter.key": value, "log.*_multiplier": m}``) in place."""
        columns = dict(self.columns)
        for key, column in MULTIPLIERS.items():
            if key in values and columns[column] is not None:
                columns[column] = np.asarray(columns[column], dtype=float) * float(values[key])
        return calibrate_accel_gps(self._scenario(values), *self.arrays, **columns, **self.options, gate=gate)

    def loglik(self, values: Mapping[str, float], *, gate: float | None = None, rejected: np.ndarray | None = None) -> float:
        """log L of the log's innovations with ``values`` in place; ``rejected`` (bool over the fixes used)
        holds a fixed set of fixes out instead of a gate: they enter as missing (prediction only)."""
        if rejected is None:
            return loglik_of(self.calibrate(values, gate=gate))
        rows = self.calibrate({}).fix_rows[np.asarray(rejected, dtype=bool)] - 1
        imu_time, accel, gps_time, gps_position, gps_velocity = self.arrays
        # a NaN in a field the fixes measure makes them missing: the position, or with velocity-only fixes
        # (no position read) the velocity
        velocity_only = 0 not in self.scenario.fix_states
        position, velocity = (None if velocity_only else np.array(gps_position, dtype=float)), np.array(gps_velocity, dtype=float)
        (velocity if velocity_only else position)[rows] = np.nan
        held = ReferenceAccelGpsLog.__new__(ReferenceAccelGpsLog)
        held.scenario, held.columns, held.options = self.scenario, self.columns, self.options
        held.arrays = (imu_time, accel, gps_time, position, velocity)
        return loglik_of(held.calibrate(values))


def prepare_reference_accel_gps_log(scenario, imu_time, accel, gps_time, gps_position, gps_velocity, **options) -> ReferenceAccelGpsLog:
    """:class:`ReferenceAccelGpsLog` of one log (the log is checked as calibrate checks it)."""
    return ReferenceAccelGpsLog(scenario, imu_time, accel, gps_time, gps_position, gps_velocity, **options)
