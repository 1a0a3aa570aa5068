"""The whiteness test's simulated null: one per capped log length, drawn by the diagnostics and cached."""

from __future__ import annotations

import functools
import threading

import numpy as np
import pandas as pd
import pytest

from kalcal.calibration import diagnostics, ljung_box
from kalcal.calibration.diagnostics import innovation_diagnostics, whiteness_null
from kalcal.scenarios.accel_gps.calibrate import compute_accel_gps_calibration
from kalcal.scenarios import build_scenario
from kalcal.scenarios.accel_gps.sampled import sample_accel_gps_logs


def _recorded(monkeypatch) -> list[tuple[str, int, int, int]]:
    """Each null drawn (the thread that drew it, its length, lags and draws), with an empty cache."""
    calls = []
    real = ljung_box._simulated.__wrapped__

    @functools.lru_cache(maxsize=16)
    def simulated(length, lags, draws):
        calls.append((threading.current_thread().name, length, lags, draws))
        return real(length, lags, draws)

    monkeypatch.setattr(ljung_box, "_simulated", simulated)
    return calls


def _logs(duration: float):
    scenario = build_scenario("accel-gps", assignments=["scenario.integration=trapezoid", f"scenario.duration={duration}"])
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(3), 1)
    imu = pd.DataFrame({"time": logs.sample_time, "accel": logs.accel[0]})
    gps = pd.DataFrame({"time": logs.fix_time, "position": logs.gps_position[0], "velocity": logs.gps_velocity[0]})
    return scenario, imu, gps


def test_every_log_of_the_reference_length_or_more_shares_one_null(monkeypatch):
    calls = _recorded(monkeypatch)
    first = whiteness_null(ljung_box.REFERENCE_FIXES, 2)
    assert whiteness_null(ljung_box.REFERENCE_FIXES + 1, 2) is first and whiteness_null(18_000, 2) is first
    assert len(calls) == 1 and calls[0][1:3] == (ljung_box.REFERENCE_FIXES, 20)
    assert whiteness_null(400, 2) is not first and whiteness_null(1, 2) is None
    assert whiteness_null(18_000, 2, confidence=0.95).size < first.size  # fewer draws for a larger tail


def test_the_diagnostics_hold_the_innovations_to_that_null(monkeypatch):
    calls = _recorded(monkeypatch)
    normalized = np.random.default_rng(0).standard_normal((700, 2))
    diagnostics = innovation_diagnostics(normalized)
    null = whiteness_null(700, 2)
    assert len(calls) == 1  # the diagnostics drew the null that whiteness_null gives
    assert diagnostics.ljung_box_upper == ljung_box.largest_passing(null, 2, (1.0 - 0.99) / 2)  # its share of alpha


@pytest.mark.parametrize("duration", [30.0, 120.0])
def test_the_job_draws_its_null_once_in_its_own_thread(monkeypatch, duration):
    """150 and 600 fixes: the diagnostics draw the null, once, in the job's thread; a second calibration
    of the same log finds it cached and the same diagnostics."""
    scenario, imu, gps = _logs(duration)
    assert gps.shape[0] == round(5 * duration)
    calls = _recorded(monkeypatch)
    first = compute_accel_gps_calibration(scenario, imu, gps)
    again = compute_accel_gps_calibration(scenario, imu, gps)
    assert [name for name, *_ in calls] == ["MainThread"]
    assert again.summary["diagnostics"] == first.summary["diagnostics"]
