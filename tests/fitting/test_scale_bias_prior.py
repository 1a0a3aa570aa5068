"""A scale-bias log's prior: diffuse unless one is given, and the conflict test between data and a given prior."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import kalcal
from kalcal.scenarios.scale_bias.calibration import calibrate_scale_bias
from kalcal.scenarios import build_scenario
from kalcal.scenarios.scale_bias.simulation import sample_scale_bias


def test_a_log_without_a_prior_is_calibrated_from_a_diffuse_one_and_one_with_a_prior_from_it():
    sim = kalcal.simulate("scale-bias", seed=3)
    diffuse = kalcal.calibrate("scale-bias", data=sim.logs["data"])
    summary = diffuse.summary
    assert summary["prior"]["kind"] == "diffuse" and summary["samples_used"] == 300 - 2
    assert diffuse.estimates["theta1"].isna().sum() == 1 and np.isfinite(diffuse.estimates["theta1"].iloc[1])
    given = kalcal.calibrate("scale-bias", data=sim.logs["data"], settings={"filter.bias_std": 0.1})
    assert given.summary["prior"]["kind"] == "settings" and given.summary["samples_used"] == 300
    assert kalcal.calibrate("scale-bias", data=sim.logs["data"], prior="settings").summary["prior"]["kind"] == "settings"
    # the diffuse estimate is the log's least squares: theta_K = argmin sum (v - theta1 z - theta2)^2 (Q = 0)
    data = sim.logs["data"]
    h = np.stack([data["sensor"], np.ones(len(data))], axis=1)
    theta = np.linalg.lstsq(h, data["reference"], rcond=None)[0]
    assert np.allclose(diffuse.estimates[["theta1", "theta2"]].iloc[-1], theta, rtol=1e-8)


def test_a_prior_far_from_the_data_is_reported_as_a_conflict():
    sim = kalcal.simulate("scale-bias", seed=3)
    result = kalcal.calibrate("scale-bias", data=sim.logs["data"], settings={"filter.bias": 2.0, "filter.bias_std": 0.05})
    codes = [w.code for w in result.warnings]
    assert "prior-conflict" in codes and result.summary["prior"]["conflict"]["conflict"]


def test_when_the_truth_is_drawn_from_the_prior_the_conflict_test_fires_at_its_rate():
    scenario = build_scenario("scale-bias", None, [])
    logs, alpha = 100, 0.01
    samples = sample_scale_bias(scenario, np.random.default_rng(11), logs)
    fired = sum(
        calibrate_scale_bias(scenario, samples.time, samples.reference[i], samples.sensor[i], conflict=True).conflict["conflict"]
        for i in range(logs)
    )
    assert fired <= stats.binom.isf(1e-3, logs, alpha)


def test_a_constant_sensor_cannot_start_from_a_diffuse_prior():
    scenario = build_scenario("scale-bias", None, [])
    with pytest.raises(kalcal.KalcalError, match="never determines theta"):
        calibrate_scale_bias(scenario, np.arange(5.0), np.ones(5), np.full(5, 2.0), prior="diffuse")
