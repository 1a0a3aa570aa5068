"""The accel-gps fit on the prepared log (O(fixes) per evaluation): its likelihood against the whole-calibration
oracle, interval coverage, latency, outliers, a rover-like log and the loop closed through filter.toml."""

from __future__ import annotations

import numpy as np
import pytest

import kalcal
from kalcal.calibration.accel_gps_log import prepare_accel_gps_log
from kalcal.fitting.accel_gps_reference import prepare_reference_accel_gps_log
from kalcal.models.registry import build_scenario


def simulated(seed, duration, settings=(), config=None):
    """One simulated log (imu, gps DataFrames) of ``duration`` s; ``settings`` as ``{"truth.key": value}``."""
    sim = kalcal.simulate("accel-gps", seed=seed, config=config, settings={"scenario.duration": duration, **dict(settings)})
    return sim.logs["imu"], sim.logs["gps"]


def both_logs(imu, gps, assignments=(), columns=False, prior="auto"):
    """The fast prepared log and the reference (whole calibration) of one log, with the same options."""
    scenario = build_scenario("accel-gps", None, ["scenario.integration=trapezoid", *assignments])
    arrays = (imu.time.values, imu.accel.values, gps.time.values, gps.position.values, gps.velocity.values)
    options = {"init": "first-fix", "prior": prior}
    if columns:
        options.update(position_std=gps.position_std.values, velocity_std=gps.velocity_std.values)
    return prepare_accel_gps_log(scenario, *arrays, **options), prepare_reference_accel_gps_log(scenario, *arrays, **options)


#: the fast and the reference runs are the same filter composed in a different order (the per-sample
#: model per interval once, against per sample per run): they agree to rounding, accumulated over a few
#: hundred samples per fix and 50 fixes, far below 1e-9 relative
REL = 1e-9


@pytest.mark.parametrize(
    "values",
    [
        {},
        {"filter.accel_noise_std": 0.07},
        {"filter.gps_position_std": 1.7, "filter.gps_velocity_std": 0.03},
        {"filter.bias_walk_std": 2e-4},
        {"filter.gps_latency": 0.02},
        {"filter.accel_noise_std": 0.01, "filter.bias_walk_std": 1e-5, "filter.gps_latency": -0.01},
        {"filter.scale_std": 1e-3},
    ],
    ids=["prepared", "accel", "gps", "walk", "latency", "mixed", "scale"],
)
def test_the_fast_likelihood_equals_the_whole_calibration(values):
    imu, gps = simulated(11, 10, {"truth.gps_position_std": 1.5, "truth.gps_latency": 0.01})
    fast, reference = both_logs(imu, gps)
    assert fast.prior == "diffuse" and fast.skip == 1  # "auto" on a log without filter.bias_std
    assert fast.fixes == reference.fixes
    assert fast.loglik(values) == pytest.approx(reference.loglik(values), rel=REL)


def test_the_fast_likelihood_with_per_fix_std_multipliers_equals_the_whole_calibration():
    imu, gps = simulated(12, 10, {"truth.gps_position_std": 2.0})
    rng = np.random.default_rng(0)
    gps = gps.assign(position_std=rng.uniform(0.8, 1.5, len(gps)), velocity_std=rng.uniform(0.02, 0.05, len(gps)))
    fast, reference = both_logs(imu, gps, columns=True)
    for values in ({}, {"log.position_std_multiplier": 1.8}, {"log.position_std_multiplier": 0.7, "log.velocity_std_multiplier": 1.3}):
        assert fast.loglik(values) == pytest.approx(reference.loglik(values), rel=REL)


def test_the_fast_likelihood_with_a_gate_that_rejects_outliers_equals_the_whole_calibration():
    truth = {"truth.gps_outlier_rate": 0.05, "truth.gps_outlier_std": 50.0}
    imu, gps = simulated(13, 20, truth)
    fast, reference = both_logs(imu, gps)
    for values in ({}, {"filter.gps_position_std": 1.3}):
        rejected = fast.calibrate(values, gate=0.999).rejected_rows
        assert 0 < rejected.size < fast.fixes // 5  # some rejected, most kept
        np.testing.assert_array_equal(rejected, reference.calibrate(values, gate=0.999).rejected_rows)
        assert fast.loglik(values, gate=0.999) == pytest.approx(reference.loglik(values, gate=0.999), rel=REL)
        assert fast.loglik(values, gate=0.999) != pytest.approx(fast.loglik(values), rel=1e-3)


def test_a_given_bias_prior_evaluates_exactly_too():
    imu, gps = simulated(14, 10)
    fast, reference = both_logs(imu, gps, ["filter.bias_std=0.1"])
    assert fast.prior == "scenario" and fast.skip == 0
    for values in ({}, {"filter.bias_std": 0.02, "filter.accel_noise_std": 0.05}):
        assert fast.loglik(values) == pytest.approx(reference.loglik(values), rel=REL)


def test_a_changed_correlation_time_is_within_dt_over_tau_of_the_whole_calibration():
    """Prepared with a constant bias (tau_0 = 0), evaluated at tau = 5 s: the fast one corrects the
    transition and the bias noise by the continuous-time model, off from the exact per-sample composition
    (the reference) by a relative amount of order dt / tau of the change it makes (docs/accel-gps.md)."""
    imu, gps = simulated(15, 10, {"truth.bias_correlation_time": 5.0, "truth.bias_std": 0.05})
    fast, reference = both_logs(imu, gps, ["filter.bias_std=0.05"])
    tau, dt = 5.0, 1.0 / 200.0
    values = {"filter.bias_correlation_time": tau}
    got, want = fast.loglik(values), reference.loglik(values)
    change = abs(want - reference.loglik({}))
    assert change > 1e-3  # the correlation time matters on this log
    assert abs(got - want) <= dt / tau * change, (got, want, change)
