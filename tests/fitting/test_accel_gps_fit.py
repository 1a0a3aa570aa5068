"""The accel-gps fit over the reference likelihood: the likelihood itself, unidentified and boundary settings,
recovery of a GPS noise within its interval, and the adequacy verdict."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import kalcal
from kalcal.scenarios.accel_gps.calibration import calibrate_accel_gps
from kalcal.scenarios.accel_gps.fit_reference import loglik_of, prepare_reference_accel_gps_log
from kalcal.scenarios import build_scenario


def logs(seed, duration, **truth):
    settings = {"scenario.duration": duration, **{f"truth.{key}": value for key, value in truth.items()}}
    sim = kalcal.simulate("accel-gps", seed=seed, settings=settings)
    return sim.logs["imu"], sim.logs["gps"]


def test_the_reference_likelihood_is_the_sum_of_the_innovations_gaussian_log_densities():
    imu, gps = logs(0, 5)
    scenario = build_scenario("accel-gps", None, ["scenario.integration=trapezoid"])
    arrays = (imu.time.values, imu.accel.values, gps.time.values, gps.position.values, gps.velocity.values)
    log = prepare_reference_accel_gps_log(scenario, *arrays, init="first-fix")
    values = {"filter.accel_noise_std": 0.05, "filter.gps_position_std": 1.7}
    changed = build_scenario(
        "accel-gps", None, ["scenario.integration=trapezoid", "filter.accel_noise_std=0.05", "filter.gps_position_std=1.7"]
    )
    calibration = calibrate_accel_gps(changed, *arrays, init="first-fix")
    expected = sum(
        stats.multivariate_normal(np.zeros(2), s).logpdf(r) for r, s in zip(calibration.residual, calibration.innovation_cov)
    )
    assert log.loglik(values) == pytest.approx(expected, rel=1e-12)
    assert loglik_of(calibration) == pytest.approx(expected, rel=1e-12)
    assert log.fixes == gps.shape[0] - 1  # the first fix starts the filter


def test_a_setting_without_influence_is_unidentified_and_a_gps_noise_is_recovered_within_its_interval():
    imu, gps = logs(2, 10, gps_position_std=2.0)
    # with the first-fix start the position prior is the first fix's noise: position0_std has no influence
    result = kalcal.fit("accel-gps", imu=imu, gps=gps, free="filter.gps_position_std,filter.position0_std")
    unused, position = result.parameters["filter.position0_std"], result.parameters["filter.gps_position_std"]
    assert not unused.identified and unused.value is None and unused.ci_low is None and "unidentified" in unused.note
    assert position.identified and position.ci_low <= 2.0 <= position.ci_high
    assert result.settings["filter"]["position0_std"] == 10.0  # the input value, kept
    assert result.converged and result.to_dict()["parameters"]["filter.position0_std"]["value"] is None


def test_bias_walk_on_a_log_without_walk_is_consistent_with_zero():
    imu, gps = logs(5, 30)
    result = kalcal.fit("accel-gps", imu=imu, gps=gps, free=["filter.bias_walk_std"])  # fitted as its density
    walk = result.parameters["filter.bias_walk_density"]
    assert walk.identified and walk.at_bound and walk.ci_low == 0.0 and walk.ci_high > walk.value
    assert "consistent with 0" in walk.note


def test_a_log_whose_bias_drifts_is_not_adequate_for_a_constant_bias_and_the_sentence_names_candidates():
    imu, gps = logs(7, 30, bias_walk_std=2e-3)
    result = kalcal.fit("accel-gps", imu=imu, gps=gps, free="filter.gps_position_std,filter.gps_velocity_std")
    assert not result.adequate and not result.diagnostics["consistent"]
    assert "a drifting bias (filter.bias_walk_density)" in result.adequacy and "time-correlated GNSS errors" in result.adequacy
    freed = kalcal.fit("accel-gps", imu=imu, gps=gps, free="filter.bias_walk_density")
    assert freed.adequate, freed.adequacy
    walk = freed.parameters["filter.bias_walk_density"]  # 2e-3 per sample at 200 Hz: K = 2e-3 sqrt(200)
    assert walk.ci_low <= 2e-3 * np.sqrt(200.0) <= walk.ci_high
    per_sample = freed.extra["per_sample"]
    assert per_sample["rate"] == pytest.approx(200.0) and per_sample["bias_walk_std"]["ci_low"] <= 2e-3 <= per_sample["bias_walk_std"]["ci_high"]


def test_per_fix_std_columns_get_one_multiplier_each_instead_of_the_constant():
    from kalcal.scenarios.accel_gps.fit import default_free

    assert default_free(True, True) == [
        "filter.accel_noise_density", "filter.bias_walk_density", "log.position_std_multiplier", "log.velocity_std_multiplier",
    ]
    imu, gps = logs(3, 10, gps_position_std=2.0)
    gps = gps.assign(position_std=1.0)  # the receiver's stated accuracy, half the truth
    result = kalcal.fit("accel-gps", imu=imu, gps=gps, free="log.position_std_multiplier")
    multiplier = result.parameters["log.position_std_multiplier"]
    assert multiplier.ci_low <= 2.0 <= multiplier.ci_high
    assert any("position_std column times one fitted multiplier" in note for note in result.notes)
    assert result.settings["truth"]["gps_position_std"] == pytest.approx(multiplier.value, rel=1e-5)
