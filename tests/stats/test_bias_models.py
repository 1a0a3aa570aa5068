"""Richer accelerometer bias models: a random walk and a first-order Gauss-Markov bias."""

import numpy as np
import pytest
from scipy.linalg import expm

from kalcal.scenarios.accel_gps.calibration import calibrate_accel_gps
from kalcal.scenarios.accel_gps.discretization import bias_discretization, error_transition
from kalcal.scenarios import build_scenario
from kalcal.montecarlo.accumulators import ensemble_statistics
from kalcal.montecarlo.engine import run_monte_carlo
from kalcal.montecarlo.scenarios import build_problem
from kalcal.scenarios.accel_gps.sampled import sample_accel_gps_errors, sample_accel_gps_logs
from kalcal.stats.suite import run_checks

WALK = ["truth.bias_walk_std=2e-4"]
MARKOV = ["truth.bias_correlation_time=5"]


def _checks(assignments, n=20000, seed=0):
    scenario = build_scenario("accel-gps", None, ["scenario.truth=discrete", *assignments])
    problem, cause = build_problem(scenario)
    stats = ensemble_statistics(run_monte_carlo(problem, n, seed).sums)
    return {c.name: c for c in run_checks(stats, problem.info, 0.99, problem.expected_mean_error(), cause)}


TRAPEZOID = ["scenario.integration=trapezoid"]


@pytest.mark.parametrize(
    "model",
    [WALK, MARKOV, WALK + TRAPEZOID, MARKOV + TRAPEZOID],
    ids=["random walk", "Gauss-Markov", "random walk, trapezoid", "Gauss-Markov, trapezoid"],
)
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
    t = scenario.truth
    samples = scenario.scenario.n_samples
    expected = t.bias_std**2 + samples * t.bias_walk_std**2 if t.bias_correlation_time == 0 else t.bias_std**2
    # sample variance of N normals: relative sd sqrt(2 / (N - 1)); 4.5 sd
    assert abs(states[:, -1, 2].var(ddof=1) / expected - 1) < 4.5 * np.sqrt(2 / 19999)
    if t.bias_correlation_time > 0:
        lag = 5.0  # one correlation time: correlation e^{-1} between the bias at 25 s and at 30 s
        k = int(round((30.0 - lag) / 0.2)) - 1
        corr = np.corrcoef(states[:, k, 2], states[:, -1, 2])[0, 1]
        assert abs(corr - np.exp(-lag / t.bias_correlation_time)) < 4.5 * (1 - np.exp(-2)) / np.sqrt(20000)


@pytest.mark.parametrize("scheme", ["euler", "trapezoid"])
def test_constant_bias_transition_is_the_matrix_exponential(scheme):
    """With a constant bias both schemes integrate it exactly: any piece of length s is exp(A s),
    A = [[0, 1, 0], [0, 0, -1], [0, 0, 0]]."""
    a = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [0.0, 0.0, 0.0]])
    for s in (1e-7, 0.005, 0.2, 3.0, 40.0):
        for start in (0.0, 0.3 * s):
            phi, noise = error_transition(start, start + s, 2.0 * s, 1.0, scheme, closes=False)
            np.testing.assert_allclose(phi, expm(a * s), rtol=1e-12, atol=1e-15)


def test_gauss_markov_discretization_is_exact_over_any_steps():
    """phi and q are the exact discrete Gauss-Markov at the sample times: stationary over any step, and two
    steps compose into their sum (the decays multiply, the variances carry)."""
    settings = build_scenario("accel-gps", None, MARKOV).truth
    steps = np.array([1e-6, 0.005, 0.37, 4.0, 60.0])
    decay, q = bias_discretization(settings, steps, 0.005)
    np.testing.assert_allclose(decay, np.exp(-steps / 5.0), rtol=1e-15)
    np.testing.assert_allclose(decay**2 * settings.bias_std**2 + q, settings.bias_std**2, rtol=1e-13)
    d1, q1 = bias_discretization(settings, 0.3, 0.005)
    d2, q2 = bias_discretization(settings, 0.45, 0.005)
    d12, q12 = bias_discretization(settings, 0.75, 0.005)
    np.testing.assert_allclose([d2 * d1, d2 * d2 * q1 + q2], [d12, q12], rtol=1e-13)
    walk = build_scenario("accel-gps", None, WALK).truth
    np.testing.assert_allclose(bias_discretization(walk, [0.005, 0.0125], 0.005)[1], [4e-8, 1e-7], rtol=1e-13)


def test_per_sample_transition_of_the_trapezoid_rule_with_a_drifting_bias():
    """The nominal integrates (b_j + b_{j+1}) / 2 over a step; b_{j+1} = phi b_j + n_j."""
    dt, phi = 0.005, 0.93
    transition, noise = error_transition(0.0, dt, dt, phi, "trapezoid")
    np.testing.assert_allclose(transition[:, 2], [-dt * dt * (2 + phi) / 6, -dt * (1 + phi) / 2, phi], rtol=1e-14)
    np.testing.assert_allclose(noise, [-dt * dt / 6, -dt / 2, 1.0], rtol=1e-14)
    # two pieces of a step, cut at a fix, carry b_j's mean the same way as the whole step
    first, _ = error_transition(0.0, 0.3 * dt, dt, phi, "trapezoid", closes=False)
    second, _ = error_transition(0.3 * dt, dt, dt, phi, "trapezoid", closes=True)
    np.testing.assert_allclose(second @ first, transition, rtol=1e-13, atol=1e-20)


@pytest.mark.parametrize("scheme", ["euler", "trapezoid"])
@pytest.mark.parametrize("decay", [1.0, 0.93], ids=["walk", "Gauss-Markov"])
def test_the_pieces_of_a_cut_step_share_its_bias_noise(scheme, decay):
    """A step cut by fixes into two or three pieces: the pieces' weights of n_j, carried to the step's end
    (T_last ... T_{i+1} g_i, summed), are the whole step's, and the transitions compose to the whole."""
    dt = 0.005
    whole_phi, whole_noise = error_transition(0.0, dt, dt, decay, scheme)
    for cuts in ([0.0, 0.3 * dt, dt], [0.0, 0.2 * dt, 0.65 * dt, dt]):
        phi, noise = np.eye(3), np.zeros(3)
        for start, end in zip(cuts[:-1], cuts[1:]):
            t, g = error_transition(start, end, dt, decay, scheme, closes=end == dt)
            phi, noise = t @ phi, t @ noise + g
        np.testing.assert_allclose(phi, whole_phi, rtol=1e-13, atol=1e-20)
        np.testing.assert_allclose(noise, whole_noise, rtol=1e-13, atol=1e-20)


@pytest.mark.parametrize(
    "bias",
    [["truth.bias_walk_std=0.2"], ["truth.bias_correlation_time=0.3", "truth.bias_std=0.5"]],
    ids=["walk", "Gauss-Markov"],
)
def test_a_fix_between_samples_takes_the_bias_noise_share_of_its_piece(bias):
    """Fixes 0.4 samples after a tick, the trapezoid rule, a drifting bias: P before and after the first
    fix equals a dense oracle, the per-sample model over the whole steps and, over the piece of length u
    into the cut step, the trapezoid's line from b_j to b_{j+1} = phi b_j + n_j integrated by hand:
    dv gains -(u + (phi - 1) u^2 / (2 dt)) b_j - u^2 / (2 dt) n_j, dp -(u^2/2 + (phi - 1) u^3 / (6 dt)) b_j
    - u^3 / (6 dt) n_j, b stays b_j; the sample's accelerometer noise adds [u^2/2, u, 0] sigma_a."""
    settings = ["scenario.integration=trapezoid", "scenario.imu_rate=10", "scenario.gps_rate=5",
                "scenario.duration=4", "truth.accel_noise_std=0.01", *bias]
    scenario = build_scenario("accel-gps", None, settings)
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(4), 1)
    dt = scenario.scenario.sample_period
    u = 0.4 * dt
    result = calibrate_accel_gps(
        scenario, logs.sample_time, logs.accel[0], logs.fix_time + u, logs.gps_position[0], logs.gps_velocity[0],
        init="prior",
    )
    model = scenario.filter_model()
    cov = model.m0
    for _ in range(scenario.scenario.steps_per_update):  # the whole steps before the first fix
        cov = model.phi @ cov @ model.phi.T + model.gamma @ model.w @ model.gamma.T
    phi, q = bias_discretization(scenario.filter_settings, dt, dt)
    piece = np.array([
        [1.0, u, -(u * u / 2 + (phi - 1) * u**3 / (6 * dt))],
        [0.0, 1.0, -(u + (phi - 1) * u * u / (2 * dt))],
        [0.0, 0.0, 1.0],
    ])
    share = np.array([-(u**3) / (6 * dt), -u * u / (2 * dt), 0.0])
    accel = np.array([u * u / 2, u, 0.0]) * scenario.filter_settings.accel_noise_std
    without_share = piece @ cov @ piece.T + np.outer(accel, accel)
    prior = without_share + q * np.outer(share, share)
    assert np.max(np.abs(prior - without_share) / np.sqrt(np.outer(np.diag(prior), np.diag(prior)))) > 1e-6
    np.testing.assert_allclose(result.prior_covariance[0], prior, rtol=1e-10, atol=0)
    v = np.diag([scenario.filter_settings.gps_position_std**2, scenario.filter_settings.gps_velocity_std**2])
    h = np.eye(3)[:2]
    gain = np.linalg.solve(h @ prior @ h.T + v, h @ prior).T
    i_kh = np.eye(3) - gain @ h
    np.testing.assert_allclose(result.covariance[0], i_kh @ prior @ i_kh.T + gain @ v @ gain.T, rtol=1e-9, atol=0)


BIAS_CASES = {
    "walk": WALK,
    "markov": MARKOV,
    "markov-and-walk": MARKOV + WALK,
    "markov-trapezoid": MARKOV + ["scenario.integration=trapezoid"],
    "walk-trapezoid": WALK + ["scenario.integration=trapezoid"],
    "markov-fast-trapezoid": ["truth.bias_correlation_time=0.05", "scenario.integration=trapezoid"],
}


@pytest.mark.parametrize("case", list(BIAS_CASES))
def test_the_filter_that_calibrates_is_the_filter_that_is_verified(case):
    """On a regular log with fixes on samples, ``calibrate``'s transitions, process noise and covariances
    are those of the filter ``verify`` runs (covariance_pass of the per-sample model), for every bias model."""
    scenario = build_scenario("accel-gps", None, ["scenario.truth=discrete", *BIAS_CASES[case]])
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(4), 1)
    result = calibrate_accel_gps(
        scenario, logs.sample_time, logs.accel[0], logs.fix_time, logs.gps_position[0], logs.gps_velocity[0], init="prior"
    )
    problem, _ = build_problem(scenario)
    schedule = problem.schedule
    np.testing.assert_allclose(result.transitions, schedule.transitions, rtol=1e-10, atol=1e-16)
    np.testing.assert_allclose(result.prior_covariance, schedule.prior_cov, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(result.covariance, schedule.posterior_cov, rtol=1e-9, atol=1e-15)


SCALE = ["truth.scale_std=1e-3"]


def test_a_filter_with_the_scale_state_is_consistent():
    checks = _checks(SCALE)
    assert all(c.passed for c in checks.values()), {n: c.detail for n, c in checks.items() if not c.passed}


def test_a_filter_that_ignores_the_scale_factor_is_overconfident():
    checks = _checks(SCALE + ["filter.scale_std=1e-9"])
    assert not checks["covariance"].passed and "overconfident" in checks["covariance"].detail


def test_scale_exact_and_sampled_engines_agree():
    """Means within 4.5 standard errors of the difference; variance ratios inside their F bounds."""
    from scipy import stats as sps

    scenario = build_scenario("accel-gps", None, [*SCALE, "scenario.duration=6", "scenario.integration=trapezoid"])
    problem, _ = build_problem(scenario)
    n = 20000
    exact = ensemble_statistics(run_monte_carlo(problem, n, seed=31, engine="exact").sums)
    sampled = ensemble_statistics(run_monte_carlo(problem, n, seed=32, engine="sampled").sums)
    var_e = np.diagonal(exact.error_cov, axis1=1, axis2=2)
    var_s = np.diagonal(sampled.error_cov, axis1=1, axis2=2)
    m = var_e.size
    assert np.all(np.abs(exact.mean_error - sampled.mean_error) <= sps.norm.isf(0.001 / (2 * m)) * np.sqrt((var_e + var_s) / n))
    low, high = sps.f.ppf([0.001 / (2 * m), 1 - 0.001 / (2 * m)], n - 1, n - 1)
    assert np.all((var_e / var_s > low) & (var_e / var_s < high))


def test_calibrating_a_scale_factor_from_logs_is_consistent():
    """30 logs with a 1% scale error: the filter of a log works in b' = b/(1+s), s' = s/(1+s), which make its
    model exact with the measured acceleration; converted back, (estimate - truth) / sigma ~ N(0, 1)."""
    from scipy import stats as sps

    scenario = build_scenario(
        "accel-gps", None, ["truth.scale_std=1e-2", "scenario.integration=trapezoid", "scenario.duration=60"]
    )
    n = 30
    z_bias, z_scale = [], []
    for seed in range(n):
        logs = sample_accel_gps_logs(scenario, np.random.default_rng(seed), 1)
        result = calibrate_accel_gps(
            scenario, logs.sample_time, logs.accel[0], logs.fix_time, logs.gps_position[0], logs.gps_velocity[0],
            init="first-fix",
        )
        z_bias.append((result.bias[-1] - logs.bias[0, -1]) / result.std[-1, 2])
        z_scale.append((result.error_state[-1, 3] - logs.scale[0]) / result.std[-1, 3])
    low, high = sps.chi2.ppf([0.0005, 0.9995], n - 1) / (n - 1)
    for z in (np.array(z_bias), np.array(z_scale)):
        assert abs(z.mean()) < sps.norm.isf(0.0005) / np.sqrt(n)
        assert low < z.var(ddof=1) < high
