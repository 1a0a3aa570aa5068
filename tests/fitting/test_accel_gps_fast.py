"""The accel-gps fit on the prepared log (O(fixes) per evaluation): its likelihood against the whole-calibration
oracle, interval coverage, latency, outliers, a rover-like log and the loop closed through filter.toml."""

from __future__ import annotations

import numpy as np
import pytest

import kalcal
from kalcal.scenarios.accel_gps.log import prepare_accel_gps_log
from kalcal.scenarios.accel_gps.fit_reference import prepare_reference_accel_gps_log
from kalcal.scenarios import build_scenario


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


#: settings of the simulated logs that differ from the defaults (0.02 m/s^2, 1 m, 0.04 m/s), per sample at
#: the simulation's 200 Hz, which is also the fit's scenario rate: the truth and the filter on one footing
COVERAGE_TRUTH = {"accel_noise_std": 0.3, "gps_position_std": 2.0, "gps_velocity_std": 0.02}


def coverage(seeds, duration):
    """How many of the logs' 95% intervals cover each true setting (unidentified: not covered)."""
    covered = dict.fromkeys(COVERAGE_TRUTH, 0)
    free = ",".join(f"filter.{key}" for key in COVERAGE_TRUTH)
    for seed in seeds:
        imu, gps = simulated(seed, duration, {f"truth.{key}": value for key, value in COVERAGE_TRUTH.items()})
        result = kalcal.fit("accel-gps", imu=imu, gps=gps, free=free)
        assert result.converged, (seed, duration)  # a clean log's fit converges
        for key, value in COVERAGE_TRUTH.items():
            if key == "accel_noise_std":  # fitted as its density: the per-sample value at 200 Hz / sqrt(200)
                p, value = result.parameters["filter.accel_noise_density"], value / np.sqrt(200.0)
            else:
                p = result.parameters[f"filter.{key}"]
            covered[key] += bool(p.identified and p.ci_low <= value <= p.ci_high)
    return covered


def assert_coverage(covered, n):
    """Each setting's count of covering intervals is no lower than a 95% interval's binomial(n, 0.95) count
    falls with probability 0.001 / 3 (three settings: at most 0.001 of failing by chance in all)."""
    from scipy import stats

    least = stats.binom.ppf(0.001 / 3, n, 0.95)
    assert all(count >= least for count in covered.values()), (covered, n, least)


def test_the_95_percent_intervals_cover_the_true_settings():
    n = 8
    assert_coverage(coverage(range(100, 100 + n), 40.0), n)


@pytest.mark.slow
def test_the_95_percent_intervals_cover_the_true_settings_at_their_rate_over_40_logs():
    n = 40
    assert_coverage(coverage(range(200, 200 + n), 60.0), n)


@pytest.mark.parametrize("seed", [217, 219, 230, 236, 239])
def test_a_clean_log_whose_search_stops_on_rounding_noise_is_converged(seed):
    """Logs of the 40-log coverage study where L-BFGS-B's line search stops on log L's rounding noise
    (about 1e-8 with the diffuse bias prior) with a gradient above mle.STATIONARY: the curvature is hundreds
    per unit of log value, so the estimate is within 1e-4 standard errors of the maximum and converged."""
    imu, gps = simulated(seed, 60.0, {f"truth.{key}": value for key, value in COVERAGE_TRUTH.items()})
    result = kalcal.fit("accel-gps", imu=imu, gps=gps, free=",".join(f"filter.{key}" for key in COVERAGE_TRUTH))
    assert result.converged


def test_a_latency_is_recovered_within_its_interval_and_calibrate_with_the_fitted_file_removes_its_bias_error(tmp_path):
    imu, gps = simulated(21, 60, {"truth.gps_latency": 0.02})
    free = "filter.accel_noise_std,filter.bias_walk_std,filter.gps_position_std,filter.gps_velocity_std,filter.gps_latency"
    result = kalcal.fit("accel-gps", imu=imu, gps=gps, free=free, out=tmp_path)
    latency = result.parameters["filter.gps_latency"]
    assert latency.identified and not latency.at_bound and latency.ci_low <= 0.02 <= latency.ci_high
    assert result.to_dict()["parameters"]["filter.gps_latency"]["start"] == 0.0  # a linear-scale search starts at the setting itself
    import tomllib

    written = tomllib.loads((tmp_path / "filter.toml").read_text())
    assert written["filter"]["gps_latency"] == pytest.approx(latency.value, rel=1e-5)
    assert written["truth"]["gps_latency"] == 0.0 and "bias_std" not in written["filter"]
    calibration = kalcal.calibrate("accel-gps", imu=imu, gps=gps, config=tmp_path / "filter.toml")
    summary = calibration.summary
    assert summary["settings"]["filter"]["gps_latency"] == pytest.approx(latency.value, rel=1e-5)
    assert summary["prior"]["bias"] == "diffuse"  # the fit's prior: filter.toml does not set filter.bias_std
    truth = kalcal.simulate("accel-gps", seed=21, settings={"scenario.duration": 60}).logs["truth"].bias.iloc[-1]
    assert abs(calibration.bias - truth) <= 3 * calibration.bias_std, (calibration.bias, truth, calibration.bias_std)


def test_verify_of_a_fitted_latency_says_how_to_verify_and_passes_that_way(tmp_path):
    imu, gps = simulated(22, 20, {"truth.gps_latency": 0.02})
    kalcal.fit("accel-gps", imu=imu, gps=gps, free="filter.gps_position_std,filter.gps_latency", out=tmp_path)
    with pytest.raises(kalcal.KalcalError, match=r"--set filter\.gps_latency=0"):
        kalcal.verify("accel-gps", config=tmp_path / "filter.toml", n=200, seed=1, long_run=0)
    verification = kalcal.verify("accel-gps", config=tmp_path / "filter.toml", n=300, seed=1, long_run=0,
                                 settings={"scenario.duration": 5, "filter.gps_latency": 0})
    assert verification.verdict == "pass"


def test_the_gate_lists_the_outliers_in_fit_json_and_keeps_the_bias_and_the_gps_noise(tmp_path):
    imu, gps = simulated(32, 60, {"truth.gps_outlier_rate": 0.03, "truth.gps_outlier_std": 50.0})
    truth = kalcal.simulate("accel-gps", seed=32, settings={"scenario.duration": 60}).logs["truth"]
    error = gps.position.values - np.interp(gps.time.values, truth.time.values, truth.position.values)
    outliers = set((np.flatnonzero(np.abs(error) > 10.0) + 1).tolist())  # 1-based rows 10 sigma off or more
    assert len(outliers) >= 5
    gated = kalcal.fit("accel-gps", imu=imu, gps=gps, gate=0.999, out=tmp_path)
    import json

    listed = json.loads((tmp_path / "fit.json").read_text())["rejected_fixes"]
    rejected = set(listed["rows"])
    assert outliers <= rejected and listed["count"] == len(rejected) == len(gated.rejected_fixes)
    # a fix that is no outlier is rejected with probability 0.001 (the gate's chi-square(2) tail)
    from scipy import stats

    assert len(rejected - outliers) <= stats.binom.ppf(0.999, gated.fixes, 0.001)
    assert gated.adequate, gated.adequacy
    if len(rejected) > stats.binom.ppf(0.999, gated.fixes, 0.001):  # more than the gate's share: said, as outliers
        assert any("read as gross outliers" in note for note in gated.notes)
    bias = truth.bias.iloc[-1]
    assert abs(gated.extra["bias"] - bias) <= 3 * gated.extra["bias_std"]
    position = gated.parameters["filter.gps_position_std"]
    assert position.ci_low <= 1.0 <= position.ci_high  # the simulation's default GPS noise, 1 m
    # without the gate the outliers are read as GPS noise: the fitted std is several times the truth
    ungated = kalcal.fit("accel-gps", imu=imu, gps=gps)
    assert ungated.parameters["filter.gps_position_std"].ci_low > 3.0
    assert ungated.rejected_fixes is None


def test_a_gated_fit_judges_adequacy_without_the_rejected_fixes():
    imu, gps = simulated(31, 30, {"truth.gps_outlier_rate": 0.03, "truth.gps_outlier_std": 50.0})
    result = kalcal.fit("accel-gps", imu=imu, gps=gps, gate=0.999, free="filter.gps_position_std")
    assert result.rejected_fixes and result.adequate, result.adequacy
    assert result.fixes == result.diagnostics["fixes"] == len(gps) - 2 - len(result.rejected_fixes)


ROVER_FREE = "filter.accel_noise_std,filter.gps_position_std,filter.gps_velocity_std"


def test_a_rover_like_log_is_adequate_with_its_gauss_markov_bias_and_not_with_a_constant_one():
    config = "examples/rover-like.toml"
    sim = kalcal.simulate("accel-gps", seed=41, config=config, settings={"scenario.duration": 60})
    imu, gps = sim.logs["imu"], sim.logs["gps"]
    markov = kalcal.fit("accel-gps", imu=imu, gps=gps, config=config,
                        free=ROVER_FREE + ",filter.bias_correlation_time,filter.bias_std")
    assert markov.adequate, markov.adequacy
    tau = markov.parameters["filter.bias_correlation_time"]
    assert tau.identified and tau.ci_low <= 30.0 <= tau.ci_high
    constant = kalcal.fit("accel-gps", imu=imu, gps=gps, config=config, free=ROVER_FREE,
                          settings={"filter.bias_correlation_time": 0, "filter.bias_walk_std": 0})
    assert not constant.adequate
    assert "candidates:" in constant.adequacy and "a Gauss-Markov bias (filter.bias_correlation_time" in constant.adequacy
