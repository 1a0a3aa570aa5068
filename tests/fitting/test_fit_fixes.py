"""Fixes of the accel-gps fit: the gate's rejected set held fixed during a search, the likelihood's fix
count, the adequacy over the fixes used, a Gauss-Markov bias's prior freed with its time, and a latency
searched on a linear scale."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import kalcal
from kalcal.scenarios.accel_gps.fit import _used
from kalcal.stats.nis import GATE_EXCESS_ALPHA, gate_excess

ROVER = Path(__file__).resolve().parents[2] / "examples" / "rover-like.toml"


def rover(seed, duration, **truth):
    settings = {"scenario.duration": duration, **{f"truth.{key}": value for key, value in truth.items()}}
    sim = kalcal.simulate("accel-gps", seed=seed, config=ROVER, settings=settings)
    return sim.logs["imu"], sim.logs["gps"]


def test_the_gated_fit_scores_one_fixed_set_of_fixes_and_does_not_reject_everything():
    imu, gps = rover(1, 120)
    result = kalcal.fit("accel-gps", imu=imu, gps=gps, gate=0.999)
    rejected = len(result.rejected_fixes)
    assert rejected < 0.01 * gps.shape[0]  # without the fixed set the search rejected 2398 of 2399 fixes
    assert result.loglik < -100.0  # not the empty sum
    assert result.fixes == gps.shape[0] - 1 - 1 - rejected  # the first fix starts the filter, the diffuse skip, the rejected


def test_a_fixed_rejected_set_is_left_out_like_missing_fixes_in_the_fast_and_the_reference_likelihood():
    from kalcal.scenarios.accel_gps.log import prepare_accel_gps_log
    from kalcal.scenarios.accel_gps.fit_reference import prepare_reference_accel_gps_log
    from kalcal.scenarios import build_scenario

    imu, gps = rover(3, 10)
    scenario = build_scenario("accel-gps", ROVER, [])
    arrays = (imu.time.values, imu.accel.values, gps.time.values, gps.position.values, gps.velocity.values)
    fast = prepare_accel_gps_log(scenario, *arrays, init="first-fix", prior="auto")
    reference = prepare_reference_accel_gps_log(scenario, *arrays, init="first-fix", prior="auto")
    mask = np.zeros(fast.fixes, dtype=bool)
    mask[[5, 17, 40]] = True
    values = {"filter.accel_noise_std": 0.3, "filter.gps_position_std": 1.5}
    held = fast.loglik(values, rejected=mask)
    assert held == pytest.approx(reference.loglik(values, rejected=mask), rel=1e-9)
    assert held > fast.loglik(values)  # three fewer terms, each a log-density below 0 here
    gated = fast.calibrate(values, gate=0.99)  # the gate's own set, held fixed, gives the gate's likelihood
    assert fast.loglik(values, rejected=gated.rejected) == pytest.approx(fast.loglik(values, gate=0.99), rel=1e-12)


@pytest.mark.parametrize(("gated", "gate"), [(50, 0.99), (1000, 0.999), (100_000, 0.99)])
def test_a_gates_excess_is_the_binomial_upper_tail(gated, gate):
    """The rule's limit u is Binomial(gated, 1 - gate)'s upper GATE_EXCESS_ALPHA quantile: P(X > u) <= alpha
    < P(X > u - 1) (so settings that describe the fixes are told otherwise with probability at most alpha,
    and no smaller limit holds that), u rejections pass and u + 1 do not."""
    from scipy import stats

    share = 1.0 - gate
    limit = int(stats.binom.isf(GATE_EXCESS_ALPHA, gated, share))
    assert stats.binom.sf(limit, gated, share) <= GATE_EXCESS_ALPHA < stats.binom.sf(limit - 1, gated, share)
    assert gate_excess(limit, gated, gate) == ""
    assert gate_excess(limit + 1, gated, gate) != ""


def test_a_gate_that_rejects_far_more_than_its_share_makes_the_fit_inadequate_and_calibrate_warns(tmp_path):
    assert gate_excess(3, 1000, 0.999) == "" and gate_excess(20, 1000, 0.999) != ""
    imu, gps = rover(2, 20)
    tight = {"filter.gps_position_std": 0.3}  # the log has 2 m
    result = kalcal.fit("accel-gps", imu=imu, gps=gps, gate=0.999, settings=tight, free="filter.bias_std")
    assert not result.adequate and "far more than its 0.001 share" in result.adequacy
    calibration = kalcal.calibrate("accel-gps", imu=imu, gps=gps, gate=0.999, settings=tight)
    assert "gate-rejects-too-many" in [w["code"] if isinstance(w, dict) else w.code for w in calibration.warnings]


def test_fixes_counts_the_likelihoods_fixes_and_adequacy_leaves_out_the_rejected_and_the_skipped():
    sim = kalcal.simulate("accel-gps", seed=4, settings={"scenario.duration": 40, "truth.gps_outlier_rate": 0.01,
                                                         "truth.gps_outlier_std": 40.0})
    imu, gps = sim.logs["imu"], sim.logs["gps"]
    result = kalcal.fit("accel-gps", imu=imu, gps=gps, gate=0.999, free="filter.gps_position_std")
    rejected = len(result.rejected_fixes)
    assert rejected >= 1
    assert result.fixes == gps.shape[0] - 2 - rejected  # the first fix starts the filter, the diffuse skip
    # mean NIS over the fixes used: 2 +- 2 / sqrt(n) for a consistent filter (4 sigma allowed); one 40 m
    # outlier against 1 m of noise alone would add about 1600 / n
    n = result.fixes
    assert result.diagnostics["mean_nis"] < 2 + 4 * 2 / np.sqrt(n)

#: the rover-like log's own model as the filter's settings
ROVER_FILTER = {"filter.accel_noise_std": 0.4, "filter.bias_std": 0.1, "filter.bias_correlation_time": 30.0,
                "filter.gps_position_std": 2.0, "filter.gps_velocity_std": 0.05}


def test_a_20_ms_latency_is_recovered_within_its_interval_on_a_linear_scale():
    sim = kalcal.simulate("accel-gps", seed=1, settings={"scenario.duration": 60, "truth.gps_latency": 0.02})
    imu, gps = sim.logs["imu"], sim.logs["gps"]
    result = kalcal.fit("accel-gps", imu=imu, gps=gps, free="filter.gps_latency")
    latency = result.parameters["filter.gps_latency"]
    assert result.converged and latency.identified and not latency.at_bound
    assert latency.ci_low <= 0.02 <= latency.ci_high
    assert latency.ci_low < 0.0 or latency.value > 0.005  # a linear scale: not stuck near a log-scale floor
    assert all(v >= -0.5 and v <= 0.5 for v in result.curves["filter.gps_latency"]["value"])
    # filter.toml: [filter] holds the fitted latency, [truth] never takes it (the log's fault)
    assert result.settings["filter"]["gps_latency"] == pytest.approx(latency.value, rel=1e-5)
    assert result.settings["truth"]["gps_latency"] == 0.0


def test_a_curve_point_beating_the_maximum_marks_the_search_not_converged():
    from kalcal.fitting.mle import Free, maximize

    # two maxima: the search from 0.1 climbs to the local one at 0.1; the curve around it reaches up the one at 0.3
    def loglik(values):
        x = values["x"]
        return float(np.log(np.exp(-((x - 0.1) ** 2) / 0.005) + 3 * np.exp(-((x - 0.3) ** 2) / 0.005) + 1e-12))

    free = [Free("x", 0.1, -1.0, 1.0, scale="linear")]
    fit = maximize(loglik, free, curve_points=41, restarts=0)
    assert not fit.converged and "local maximum" in fit.message
    assert fit.values["x"] == pytest.approx(0.1, abs=1e-3)
    again = maximize(loglik, free, curve_points=41)  # restarted from the curve's better point
    assert again.converged and again.values["x"] == pytest.approx(0.3, abs=1e-3)


def test_freeing_the_correlation_time_alone_frees_the_gauss_markov_prior_too():
    imu, gps = rover(5, 20)
    result = kalcal.fit("accel-gps", imu=imu, gps=gps, free="filter.bias_correlation_time")
    assert "filter.bias_std" in result.parameters
    assert any("filter.bias_std freed with filter.bias_correlation_time" in note for note in result.notes)


def test_without_a_positive_definite_observed_information_the_interval_is_the_profiles(monkeypatch):
    from kalcal.fitting import mle

    # log L = -1/2 u^T A u in u = log(value), correlation 0.9: the profile's 95% half-width is
    # 1.96 sqrt(Sigma_11) = 1.96, the slice's only 1.96 sqrt(1 - 0.81) = 0.85
    cov = np.array([[1.0, 0.9], [0.9, 1.0]])
    precision = np.linalg.inv(cov)

    def loglik(values):
        u = np.log([values["a"], values["b"]])
        return float(-0.5 * u @ precision @ u)

    monkeypatch.setattr(mle, "_hessian", lambda f, u, index: -np.eye(len(index)))  # not positive definite
    free = [mle.Free("a", 1.0, 1e-3, 1e3), mle.Free("b", 1.0, 1e-3, 1e3)]
    fit = mle.maximize(loglik, free)
    a = fit.parameters["a"]
    assert "profile likelihood" in a.note
    z = 1.959963984540054
    assert np.log(a.ci_high) == pytest.approx(z * np.sqrt(cov[0, 0]), abs=2e-3)
    assert np.log(a.ci_low) == pytest.approx(-z * np.sqrt(cov[0, 0]), abs=2e-3)


def test_the_terminal_names_the_gates_rejected_fixes(tmp_path):
    from typer.testing import CliRunner

    from kalcal.cli import app

    sim = kalcal.simulate("accel-gps", seed=4, settings={"scenario.duration": 20, "truth.gps_outlier_rate": 0.02,
                                                         "truth.gps_outlier_std": 40.0})
    paths = sim.save(tmp_path / "sim")
    imu, gps = paths["imu"], paths["gps"]
    result = CliRunner().invoke(app, ["fit", "accel-gps", "--imu", str(imu), "--gps", str(gps), "--out",
                                      str(tmp_path / "fit"), "--free", "filter.gps_position_std", "--gate", "0.999"],
                                catch_exceptions=False)
    assert result.exit_code == 0, result.stdout
    import json

    document = json.loads((tmp_path / "fit" / "fit.json").read_text())
    rejected = document["rejected_fixes"]["rows"]
    assert rejected and f"gate 0.999: {len(rejected)} fix(es) rejected (GPS rows {rejected[0]}" in result.stdout


def test_a_fitted_multipliers_truth_is_the_multiplier_times_the_columns_median():
    sim = kalcal.simulate("accel-gps", seed=6, settings={"scenario.duration": 10})
    imu, gps = sim.logs["imu"], sim.logs["gps"].copy()
    gps["position_std"] = np.where(np.arange(len(gps)) % 2 == 0, 0.5, 0.8)  # median 0.65 (an even count: 0.65)
    result = kalcal.fit("accel-gps", imu=imu, gps=gps, free="log.position_std_multiplier")
    factor = result.parameters["log.position_std_multiplier"].value
    median = float(np.median(gps["position_std"]))
    assert result.settings["truth"]["gps_position_std"] == pytest.approx(factor * median, rel=1e-5)
    assert result.settings["filter"]["gps_position_std"] == result.settings["truth"]["gps_position_std"]
