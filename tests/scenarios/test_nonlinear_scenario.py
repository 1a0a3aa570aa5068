"""The nonlinear scenario (a model written as code): its Monte Carlo, effect sizes, tolerance verdicts,
the Cramér–Rao bound, the batch capability and the CLI. Fixed seeds; bounds from theory."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats as sps

from kalcal.core import xmath as xm
from kalcal.core.nonlinear import NonlinearModel, load_nonlinear_model
from kalcal.errors import ConfigError
from kalcal.montecarlo.accumulators import ensemble_statistics
from kalcal.montecarlo.engine import run_monte_carlo
from kalcal.scenarios import load_code_model
from kalcal.scenarios.protocol import Capabilities, require
from kalcal.stats.suite import run_checks

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "range_bearing.py"
rb = load_nonlinear_model(EXAMPLE)


def _linear_h(x, data):
    return xm.stack([x[:, 0] + 0.5 * x[:, 2], x[:, 1]])


def linear_model(r_scale: float = 1.0) -> NonlinearModel:
    """The range-bearing model's constant-velocity f with a linear measurement: its EKF is the Kalman filter."""
    m = rb.filter
    return NonlinearModel(
        f=m.f, h=_linear_h, q=m.q, r=np.diag([1.0, 4.0]) * r_scale, x0=m.x0, p0=m.p0, dt=1.0,
        state_names=m.state_names, state_units=m.state_units, measurement_names=("a", "b"), measurement_units=("m", "m"),
    )


def _run(scenario, n, seed=3, workers=1):
    problem = scenario.problem()
    run = run_monte_carlo(problem, n, seed, workers=workers)
    return problem, run, problem.effect_sizes(run.sums, 0.99)


def test_linear_model_as_code_passes_every_exact_check_and_its_bound_is_the_riccati_p():
    scenario = load_code_model(linear_model(), ["scenario.updates=30"])
    problem, run, effects = _run(scenario, 2000)
    checks = run_checks(ensemble_statistics(run.sums), problem.info, 0.99)
    # the shape check too: the Kalman filter's NEES and NIS are exactly chi-square(4) and chi-square(2)
    assert [c.name for c in checks] == ["mean_error", "covariance", "orthogonality", "residual_whiteness", "nis", "shape"]
    assert all(c.passed for c in checks), [(c.name, c.pvalue) for c in checks]
    # the EKF of a linear model is the Kalman filter: every realization's P_k is the Riccati P_k, and the
    # posterior Cramér–Rao bound of a linear Gaussian model is that P_k
    riccati = run.sums.filter_cov / run.sums.count
    bound = effects.cramer_rao.bound
    assert effects.cramer_rao.reason.startswith("tichavsky")
    assert np.max(np.abs(bound - riccati)) <= 1e-10 * np.max(np.abs(riccati))
    assert effects.within_tolerance()
    nees = next(e for e in effects.overall if e.name == "nees_per_dim")
    assert nees.lower <= 1.0 <= nees.upper


def test_static_parameters_bound_is_the_summed_information():
    """Q = 0 and f(x) = x: J_k = J_0 + sum_j H_j^T R^-1 H_j (a linear h: exactly the batch information)."""
    h = np.array([[1.0, 0.5], [0.0, 1.0]])
    r = np.diag([1.0, 2.0])
    model = NonlinearModel(
        f=lambda x, u, dt: x * 1.0, h=lambda x, data: xm.stack([x[:, 0] + 0.5 * x[:, 1], x[:, 1]]),
        q=np.zeros((2, 2)), r=r, x0=[0.0, 0.0], p0=np.eye(2) * 4.0, dt=1.0,
        state_names=("a", "b"), state_units=("1", "1"), measurement_names=("y1", "y2"), measurement_units=("1", "1"),
    )
    _, _, effects = _run(load_code_model(model, ["scenario.updates=5"]), 200)
    info = np.linalg.inv(np.eye(2) * 4.0) + np.arange(1, 6)[:, None, None] * (h.T @ np.linalg.solve(r, h))
    assert effects.cramer_rao.reason.startswith("static")
    np.testing.assert_allclose(effects.cramer_rao.bound, np.linalg.inv(info), rtol=1e-12)


def test_range_bearing_ekf_mse_is_not_below_the_bound_beyond_its_monte_carlo_error():
    scenario = load_code_model(str(EXAMPLE))
    _, run, effects = _run(scenario, 2000)
    crb = effects.cramer_rao
    # one-sided at 0.999 per comparison, Bonferroni over K d comparisons: a correct bound is crossed by
    # chance with probability at most 0.001
    z = sps.norm.isf(0.001 / crb.mse.size)
    bound = np.diagonal(crb.bound, axis1=1, axis2=2)
    assert np.all(crb.mse + z * crb.mse_se >= bound)
    # the bound is informative, not vacuous: within a factor of 3 of the MSE at the end
    assert np.all(bound[-1] > crb.mse[-1] / 3)


def test_mistuned_filter_fails_the_tolerance_verdict():
    """The filter believes R x 4: its P exceeds the mean squared error, far outside +-10 %."""
    truth, belief = linear_model(), linear_model(4.0)
    scenario = load_code_model((truth, belief), ["scenario.updates=30"])
    _, _, effects = _run(scenario, 2000)
    ratios = [e for e in effects.overall if e.name == "variance_ratio"]
    assert not effects.within_tolerance()
    assert any(not e.within_tolerance and e.upper < e.tolerance_lower for e in ratios)


def test_same_seed_same_sums_whatever_the_workers():
    scenario = load_code_model(str(EXAMPLE), ["scenario.updates=10"])
    problem = scenario.problem()
    one = run_monte_carlo(problem, 5000, 7, workers=1).sums
    two = run_monte_carlo(problem, 5000, 7, workers=2).sums
    np.testing.assert_array_equal(one.effect, two.effect)
    np.testing.assert_array_equal(one.error_outer, two.error_outer)


def test_streamed_sums_match_the_numpy_block():
    """block_sums (update by update) against run_block's whole arrays, same draws."""
    from kalcal.montecarlo.accumulators import MomentSums
    from kalcal.montecarlo.engine import block_generator

    problem = load_code_model(str(EXAMPLE), ["scenario.updates=8"]).problem()
    streamed = problem.block_sums(block_generator(1, 0), 300, "exact")
    oracle = MomentSums.from_block(problem.run_block(block_generator(1, 0), 300, "exact"))
    for name in ("error_outer", "nees", "nis", "whitened_outer", "filter_cov", "residual_outer"):
        np.testing.assert_allclose(getattr(streamed, name), getattr(oracle, name), rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("kind", ["iekf", "ukf"])
def test_other_filters_run_with_effect_sizes(kind):
    scenario = load_code_model(str(EXAMPLE), [f"filter.kind={kind}", "scenario.updates=20"])
    _, _, effects = _run(scenario, 500)
    assert {e.name for e in effects.overall} >= {"nees_per_dim", "variance_ratio", "bias_sigma", "whiteness_lag1"}


def test_commands_it_lacks_are_refused_in_one_line():
    scenario = load_code_model(str(EXAMPLE))
    for command in ("analyze", "calibrate", "fit"):
        with pytest.raises(ConfigError, match="model written as code") as info:
            require(scenario, command)
        assert "\n" not in str(info.value)


def test_batch_estimator_gets_the_final_time_checks_only():
    scenario = load_code_model(linear_model(), ["scenario.updates=10"])
    problem = scenario.problem()
    run = run_monte_carlo(problem, 500, 2, workers=1)
    caps = dataclasses.replace(scenario.capabilities, batch=True)
    info = dataclasses.replace(problem.info, capabilities=caps)
    checks = run_checks(ensemble_statistics(run.sums), info, 0.99)
    assert [c.name for c in checks] == ["mean_error", "covariance", "nis", "shape"]  # a batch ML is no posterior mean
    d = 4
    assert checks[0].comparisons == d  # K = 1: one update's d states
    assert checks[2].comparisons == 1
    assert checks[3].comparisons == 2  # the final update's NEES and NIS histograms
    parts = {part.name: part for part in checks[3].parts}
    # each part's bound is the Kolmogorov-Smirnov one of one comparison at alpha / 2 over N = 500 values
    from kalcal.stats.shape import ks_bound

    assert parts["nees"].upper == parts["nis"].upper == ks_bound(0.005, 1, 500)


def _cli(*args, cwd=None):
    env = dict(os.environ)
    return subprocess.run([sys.executable, "-m", "kalcal", *args], capture_output=True, text=True, env=env, cwd=cwd)


def test_cli_writes_effect_sizes_and_the_bound(tmp_path):
    out = tmp_path / "out"
    done = _cli("verify", str(EXAMPLE), "-n", "2000", "--out", str(out), "--set", "scenario.updates=20")
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["effect_sizes"]["tolerance"] == 0.1
    names = {e["name"] for e in summary["effect_sizes"]["overall"]}
    assert names == {"nees_per_dim", "variance_ratio", "bias_sigma", "whiteness_lag1", "nis_per_dim"}
    assert [r["state"] for r in summary["cramer_rao"]["final"]] == ["px", "py", "vx", "vy"]
    # the posterior bound holds for every estimator, biased or not; 2000 realizations are one block of the
    # engine, too few groups for the jackknife: the bound's own error is not available and below_bound's
    # error is the MSE's alone, as each row says
    note = summary["cramer_rao"]["note"]
    assert "unbiased" not in note and "biased or not" in note and "jackknife" in note
    assert summary["cramer_rao"]["jackknife_groups"] == 1 and summary["cramer_rao"]["bound_diagonal_se"] is None
    for row in summary["cramer_rao"]["final"]:
        assert row["below_bound_error"].startswith("the MSE's Monte Carlo error only") and row["lower_bound_se"] is None
    covariance = next(t for t in summary["tests"] if t["name"] == "covariance")
    assert covariance["within_tolerance"] in (True, False) and covariance["effect_sizes"]
    page = (out / "report.html").read_text()
    assert "Effect sizes" in page and "Cramér–Rao" in page
    assert "unbiased estimator" not in page and "biased or not" in page


def test_cli_bad_file_is_one_line_exit_2(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text("x = 1\n")
    done = _cli("verify", str(bad), "-n", "200", "--out", str(tmp_path / "o"))
    assert done.returncode == 2
    assert len(done.stderr.strip().splitlines()) == 1 and "bad.py" in done.stderr
    done = _cli("verify", str(EXAMPLE), "-n", "200", "--out", str(tmp_path / "o2"), "--set", "filter.kind=pf")
    assert done.returncode == 2 and "filter.kind" in done.stderr
