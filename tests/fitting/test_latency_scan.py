"""The latency's likelihood scanned over its range: on a rover-like log it is rough at the sample scale, and
the fit says the latency is not resolved, never a narrow interval about one maximum."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import kalcal
from kalcal.scenarios.accel_gps.log import prepare_accel_gps_log
from kalcal.scenarios.accel_gps.latency_scan import UNRESOLVED, scan_step
from kalcal.scenarios import build_scenario

ROVER = Path(__file__).resolve().parents[2] / "examples" / "rover-like.toml"


@pytest.mark.parametrize("seed, latency", [(5, 0.0), (6, 0.02)])
def test_a_rover_like_logs_latency_is_not_resolved_and_never_given_a_narrow_interval(seed, latency):
    sim = kalcal.simulate("accel-gps", seed=seed, config=ROVER, settings={"scenario.duration": 60, "truth.gps_latency": latency})
    imu, gps = sim.logs["imu"], sim.logs["gps"]
    # the filter is the log's own model (the config's truth), the latency alone free
    result = kalcal.fit("accel-gps", imu=imu, gps=gps, config=ROVER, settings={"truth.gps_latency": 0},
                        free="filter.gps_latency")
    p = result.parameters["filter.gps_latency"]
    assert not p.identified and p.held and p.value is None and p.ci_low is None and p.ci_high is None, p
    assert p.note.startswith(UNRESOLVED) and any(note.startswith(f"filter.gps_latency: {UNRESOLVED}") for note in result.notes)
    # adequacy is the diagnostics' at the written point (the input latency), not the latency's resolution
    tail = result.diagnostics["nis_tail"]
    assert result.adequate == (result.diagnostics["consistent"] and tail["passed"]) and UNRESOLVED not in result.adequacy
    assert result.settings["filter"]["gps_latency"] == 0.0  # the input setting kept
    assert UNRESOLVED in result.comments["gps_latency"]
    # an independent scan at 1 ms: the fit's scan found the highest maximum in the range; its curvature changes
    # from point to point by more than the roughness rule allows
    scenario = build_scenario("accel-gps", ROVER, ["truth.gps_latency=0", "scenario.integration=trapezoid"])
    log = prepare_accel_gps_log(scenario, imu.time.values, imu.accel.values, gps.time.values, gps.position.values,
                                gps.velocity.values, init="first-fix", prior="auto")
    grid = np.arange(-0.2, 0.2001, 0.001)
    loglik = np.array([log.loglik({"filter.gps_latency": x}) for x in grid])
    assert loglik.max() <= max(result.curves["filter.gps_latency"]["loglik"]) + 1e-4
    # fit.json's log L is the written point's: the input latency
    assert result.loglik == pytest.approx(loglik[np.argmin(np.abs(grid))], abs=1e-6)
    # and so are its diagnostics: those of this independent calibration at the input latency
    calibration = log.calibrate({})
    innovations = calibration.normalized_innovations[int(calibration.skip or 0):]
    assert result.diagnostics["fixes"] == innovations.shape[0]
    assert result.diagnostics["mean_nis"] == pytest.approx(float(np.mean(np.sum(innovations**2, axis=1))), rel=1e-9)


def test_the_scan_steps_half_an_accelerometer_sample():
    assert scan_step(200.0) == 0.0025
