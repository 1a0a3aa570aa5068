"""Richer accelerometer bias models: a random walk and a first-order Gauss-Markov bias."""

import numpy as np
import pytest
from scipy.linalg import expm

from kalcal.calibrate.accel_gps import calibrate_accel_gps, transition
from kalcal.filters.kalman import covariance_pass
from kalcal.models.registry import build_scenario
from kalcal.montecarlo.accumulators import ensemble_statistics
from kalcal.montecarlo.engine import run_monte_carlo
from kalcal.montecarlo.scenarios import build_problem
from kalcal.simulate.sampled import sample_accel_gps_errors, sample_accel_gps_logs
from kalcal.verify.checks import run_checks

WALK = ["truth.bias_walk_std=2e-4"]
MARKOV = ["truth.bias_correlation_time=5"]


def _checks(assignments, n=20000, seed=0):
    scenario = build_scenario("accel-gps", None, ["scenario.truth=discrete", *assignments])
    problem, cause = build_problem(scenario)
    stats = ensemble_statistics(run_monte_carlo(problem, n, seed).sums)
    return {c.name: c for c in run_checks(stats, problem.info, 0.99, problem.expected_mean_error(), cause)}


@pytest.mark.parametrize("model", [WALK, MARKOV], ids=["random walk", "Gauss-Markov"])
def test_a_filter_that_models_the_drift_is_consistent(model):
    checks = _checks(model)
    assert all(c.passed for c in checks.values()), {n: c.detail for n, c in checks.items() if not c.passed}


@pytest.mark.parametrize(
    "model", [WALK + ["filter.bias_walk_std=0"], MARKOV + ["filter.bias_correlation_time=0"]], ids=["walk", "markov"]
)
def test_a_filter_that_ignores_the_drift_is_overconfident(model):
    checks = _checks(model)
    assert not checks["covariance"].passed and "overconfident" in checks["covariance"].detail


@pytest.mark.parametrize("model", [WALK, MARKOV], ids=["random walk", "Gauss-Markov"])
def test_gauss_markov_and_walk_bias_statistics_of_the_sampler(model):
    """The per-sample bias path: its variance at 30 s is sigma_b^2 + K q_b (walk) or sigma_b^2 (stationary)."""
    scenario = build_scenario("accel-gps", None, model)
    states, _ = sample_accel_gps_errors(scenario, np.random.default_rng(3), 20000)
    t, dt = scenario.truth, scenario.scenario.sample_period
    samples = scenario.scenario.n_samples
    expected = t.bias_std**2 + samples * t.bias_walk_std**2 if t.bias_correlation_time == 0 else t.bias_std**2
    # sample variance of N normals: relative sd sqrt(2 / (N - 1)); 4.5 sd
    assert abs(states[:, -1, 2].var(ddof=1) / expected - 1) < 4.5 * np.sqrt(2 / 19999)
    if t.bias_correlation_time > 0:
        lag = 5.0  # one correlation time: correlation e^{-1} between the bias at 25 s and at 30 s
        k = int(round((30.0 - lag) / 0.2)) - 1
        corr = np.corrcoef(states[:, k, 2], states[:, -1, 2])[0, 1]
        assert abs(corr - np.exp(-lag / t.bias_correlation_time)) < 4.5 * (1 - np.exp(-2)) / np.sqrt(20000)


@pytest.mark.parametrize("tau", [0.0, 5.0, 1e6])
def test_transition_is_the_matrix_exponential(tau):
    rate = 1 / tau if tau > 0 else 0.0
    a = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [0.0, 0.0, -rate]])
    for s in (1e-7, 0.005, 0.2, 3.0, 40.0):
        np.testing.assert_allclose(transition(s, tau), expm(a * s), rtol=1e-12, atol=1e-15)


def test_calibrating_a_walk_matches_the_covariance_pass():
    """On a regular log the real-log path's covariance (pieces, closed forms) equals the per-sample model's."""
    scenario = build_scenario("accel-gps", None, ["scenario.truth=discrete", *WALK])
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(4), 1)
    result = calibrate_accel_gps(
        scenario, logs.sample_time, logs.accel[0], logs.fix_time, logs.gps_position[0], logs.gps_velocity[0], init="prior"
    )
    expected = covariance_pass(scenario.filter_model(), scenario.scenario.n_updates).posterior_cov
    np.testing.assert_allclose(result.covariance, expected, rtol=1e-9, atol=1e-15)
