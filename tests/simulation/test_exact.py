"""Exact sampling at the update rate against the per-sample simulation and the dense joint Gaussian.

The dense oracle writes every error state at the fixes as a linear map of the independent draws
(initial offsets, bias, every accelerometer noise sample) plus the deterministic model error, with the
integration done by a plain loop here, and gives their exact mean and covariance.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest

from kalcal.core.model import LinearGaussianModel
from kalcal.core.steps import interval_transition
from kalcal.scenarios.accel_gps.mechanization import interval_weights
from kalcal.scenarios import build_scenario
from kalcal.scenarios.accel_gps.truth import accel_gps_model_error, accel_gps_truth
from kalcal.simulation.exact import sample_exact, truth_from_model
from kalcal.scenarios.accel_gps.sampled import sample_accel_gps_errors
from tests._helpers import assert_gaussian_moments, assert_same_distribution

N = 20_000

# Small initial uncertainty and loud accelerometer noise, so the noise and the model error dominate.
NOISY = [
    "truth.accel_noise_std=0.5",
    "truth.position0_std=0.1",
    "truth.velocity0_std=0.1",
    "truth.bias_std=0.05",
    "truth.gps_position_std=0.1",
    "truth.gps_velocity_std=0.05",
]
CONFIGS = {
    "euler-analytic": ["scenario.integration=euler", "scenario.truth=analytic", "scenario.duration=6"],
    "trapezoid-analytic": ["scenario.integration=trapezoid", "scenario.truth=analytic", "scenario.duration=6"],
    # Prior means of the filter apart from the truth's: the error state has a non-zero mean.
    "euler-discrete": [
        "scenario.integration=euler",
        "scenario.truth=discrete",
        "scenario.duration=6",
        "filter.position0_mean=2",
        "filter.velocity0_mean=99.5",
    ],
    # Two and one samples per fix: the trapezoid's shared boundary sample matters most.
    "trapezoid-analytic-m2": [
        "scenario.integration=trapezoid",
        "scenario.truth=analytic",
        "scenario.imu_rate=10",
        "scenario.gps_rate=5",
        "scenario.duration=4",
        *NOISY,
    ],
    "euler-analytic-m2": [
        "scenario.integration=euler",
        "scenario.truth=analytic",
        "scenario.imu_rate=10",
        "scenario.gps_rate=5",
        "scenario.duration=4",
        *NOISY,
    ],
    "trapezoid-discrete-m1": [
        "scenario.integration=trapezoid",
        "scenario.truth=discrete",
        "scenario.imu_rate=5",
        "scenario.gps_rate=5",
        "scenario.duration=4",
        *NOISY,
    ],
    # A drifting bias: the trapezoid rule integrates the line between two bias samples, so the bias's
    # own noise enters dp and dv within the step it is drawn in (loud, to make that visible).
    "trapezoid-walk-m2": [
        "scenario.integration=trapezoid",
        "scenario.truth=analytic",
        "scenario.imu_rate=10",
        "scenario.gps_rate=5",
        "scenario.duration=4",
        "truth.bias_walk_std=0.05",
        *NOISY,
    ],
    "trapezoid-markov-m2": [
        "scenario.integration=trapezoid",
        "scenario.truth=discrete",
        "scenario.imu_rate=10",
        "scenario.gps_rate=5",
        "scenario.duration=4",
        "truth.bias_correlation_time=0.3",
        *NOISY,
        "truth.bias_std=0.5",
    ],
    "euler-markov-walk-m2": [
        "scenario.integration=euler",
        "scenario.truth=analytic",
        "scenario.imu_rate=10",
        "scenario.gps_rate=5",
        "scenario.duration=4",
        "truth.bias_correlation_time=0.3",
        "truth.bias_walk_std=0.05",
        *NOISY,
        "truth.bias_std=0.5",
    ],
    "trapezoid-markov-walk": [
        "scenario.integration=trapezoid",
        "scenario.truth=discrete",
        "scenario.duration=6",
        "truth.bias_correlation_time=2",
        "truth.bias_walk_std=2e-3",
        "filter.velocity0_mean=99.5",
    ],
}


def _scenario(name):
    return build_scenario("accel-gps", assignments=CONFIGS[name])


def _loop_integrate(accel, dt, scheme):
    """The schemes' recursions from rest, one sample at a time, over the last axis."""
    accel = np.asarray(accel, dtype=float)
    p = np.zeros(accel.shape)
    v = np.zeros(accel.shape)
    for j in range(accel.shape[-1] - 1):
        if scheme == "euler":
            a, a_position = accel[..., j], accel[..., j] / 2
        else:
            a, a_position = 0.5 * (accel[..., j] + accel[..., j + 1]), (2 * accel[..., j] + accel[..., j + 1]) / 6
        v[..., j + 1] = v[..., j] + a * dt
        p[..., j + 1] = p[..., j] + v[..., j] * dt + a_position * dt * dt
    return p, v


def _report_motion(t, amplitude, omega):
    """The report's closed form minus p0 + v0 t and v0."""
    return amplitude / omega * t - amplitude / omega**2 * np.sin(omega * t), amplitude / omega * (1 - np.cos(omega * t))


@lru_cache(maxsize=None)
def _dense_moments(name):
    """Exact mean (K, 3) and covariance (3K, 3K) of the error states at the fixes, and V (2, 2)."""
    scenario = _scenario(name)
    s, t, f = scenario.scenario, scenario.truth, scenario.filter_settings
    dt, n_samples = s.sample_period, s.n_samples
    fix = np.arange(1, s.n_updates + 1) * s.steps_per_update
    tk = fix * dt
    # Response to a unit impulse at each accelerometer sample, at every sample: (J + 1, J + 1).
    gp, gv = _loop_integrate(np.eye(n_samples + 1), dt, s.integration)
    gp, gv = gp[:, fix], gv[:, fix]  # (J + 1, K)
    if s.truth == "analytic":
        a = t.accel_amplitude * np.sin(t.accel_frequency * np.arange(n_samples + 1) * dt)
        pa, va = _loop_integrate(a, dt, s.integration)
        mp, mv = _report_motion(tk, t.accel_amplitude, t.accel_frequency)
        dp_det, dv_det = mp - pa[fix], mv - va[fix]
    else:
        dp_det = dv_det = np.zeros(s.n_updates)
    offset_p, offset_v = t.position0_mean - f.position0_mean, t.velocity0_mean - f.velocity0_mean
    mean = np.stack([offset_p + offset_v * tk + dp_det, offset_v + dv_det, np.zeros(s.n_updates)], axis=1)
    # The bias at every sample, written out from the per-sample recursion b_{j+1} = phi b_j + sqrt(q) n_j
    # (phi = e^{-dt/tau}, q = bias_std^2 (1 - phi^2) + bias_walk_std^2), as a map of [b_0, n_0 .. n_{J-1}].
    phi = np.exp(-dt / t.bias_correlation_time) if t.bias_correlation_time > 0 else 1.0
    q = t.bias_walk_std**2 + (t.bias_std**2 * (1 - phi**2) if t.bias_correlation_time > 0 else 0.0)
    j = np.arange(n_samples + 1)
    path = np.zeros((n_samples + 1, 1 + n_samples))
    path[:, 0] = phi**j
    lag = j[:, None] - 1 - np.arange(n_samples)[None, :]
    path[:, 1:] = np.where(lag >= 0, np.sqrt(q) * phi ** np.maximum(lag, 0), 0.0)
    # Draws xi = [p0, v0, w_0 .. w_J, b_0, n_0 .. n_{J-1}], independent with these variances; the nominal
    # integrates a_c = a + b + w sample by sample, so b_j enters exactly as w_j does.
    var = np.concatenate(
        [
            [t.position0_std**2, t.velocity0_std**2],
            np.full(n_samples + 1, t.accel_noise_std**2),
            [t.bias_std**2],
            np.ones(n_samples),
        ]
    )
    k = s.n_updates
    w = slice(2, 3 + n_samples)
    bias = slice(3 + n_samples, None)
    b = np.zeros((k, 3, var.size))
    b[:, 0, 0], b[:, 0, 1], b[:, 0, w], b[:, 0, bias] = 1.0, tk, -gp.T, -gp.T @ path
    b[:, 1, 1], b[:, 1, w], b[:, 1, bias] = 1.0, -gv.T, -gv.T @ path
    b[:, 2, bias] = path[fix]
    b = b.reshape(3 * k, -1)
    cov = (b * var) @ b.T
    v = np.diag([t.gps_position_std**2, t.gps_velocity_std**2])
    return mean, cov, v


@lru_cache(maxsize=None)
def _ensembles(name):
    scenario = _scenario(name)
    sampled = sample_accel_gps_errors(scenario, np.random.default_rng(20240), N)
    exact = sample_exact(accel_gps_truth(scenario), np.random.default_rng(20241), N)
    return sampled, exact


def _pairs(n_updates):
    return [(0, 1), (n_updates // 2, n_updates // 2 + 1), (n_updates - 2, n_updates - 1)]


def _stack(states, measurements, k):
    """[x_k, x_{k+1}, z_k, z_{k+1}] per realization, (N, 10)."""
    return np.concatenate([states[:, k], states[:, k + 1], measurements[:, k], measurements[:, k + 1]], axis=1)


def _pair_moments(name, k):
    mean, cov, v = _dense_moments(name)
    h = np.array([[1.0, 0, 0], [0, 1.0, 0]])
    idx = np.r_[3 * k : 3 * k + 6]
    c6 = cov[np.ix_(idx, idx)]
    hb = np.kron(np.eye(2), h)
    full = np.block([[c6, c6 @ hb.T], [hb @ c6, hb @ c6 @ hb.T + np.kron(np.eye(2), v)]])
    mu6 = mean[k : k + 2].ravel()
    return np.concatenate([mu6, hb @ mu6]), full


# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(CONFIGS))
def test_exact_and_sampled_agree_in_distribution(name):
    (s_states, s_meas), (e_states, e_meas) = _ensembles(name)
    assert s_states.shape == e_states.shape and s_meas.shape == e_meas.shape
    for k, _ in _pairs(s_states.shape[1]):
        assert_same_distribution(
            _stack(s_states, s_meas, k), _stack(e_states, e_meas, k), what=f"{name}, updates {k}, {k + 1}"
        )


@pytest.mark.parametrize("sampler", ["sampled", "exact"])
@pytest.mark.parametrize("name", sorted(CONFIGS))
def test_sampler_matches_dense_joint_gaussian(name, sampler):
    (s_states, s_meas), (e_states, e_meas) = _ensembles(name)
    states, meas = (s_states, s_meas) if sampler == "sampled" else (e_states, e_meas)
    for k, _ in _pairs(states.shape[1]):
        mean, cov = _pair_moments(name, k)
        assert_gaussian_moments(_stack(states, meas, k), mean, cov, what=f"{name} {sampler}, updates {k}, {k + 1}")


@pytest.mark.parametrize("name", sorted(CONFIGS))
def test_exact_model_error_equals_dense_oracle(name):
    scenario = _scenario(name)
    mean, _, _ = _dense_moments(name)
    offset = scenario.truth_model().x0
    tk = scenario.scenario.update_times()
    deterministic = mean - np.stack([offset[0] + offset[1] * tk, np.full(tk.size, offset[1]), np.zeros(tk.size)], 1)
    # D is a small difference of large numbers: allow the rounding of J additions at the motion's size.
    t = scenario.truth
    motion = np.abs(_report_motion(tk, t.accel_amplitude, t.accel_frequency)).max()
    rounding = scenario.scenario.n_samples * np.finfo(float).eps * max(motion, 1.0)
    np.testing.assert_allclose(accel_gps_model_error(scenario), deterministic, rtol=0, atol=rounding)


def _update_rate_moments(truth):
    """Mean (K, d) and the covariances Cov(x_k, x_k), Cov(x_k, x_{k+1}) of the exact sampler's model.

    y_{k+1} = A_k y_k + L xi_k + b_in u_k + b_out u_{k+1}: with C_k = Cov(y_k, u_k) (0 at k = 0),
    Cov(y_{k+1}) = A S A^T + L L^T + b_in b_in^T + b_out b_out^T + A C b_in^T + b_in C^T A^T, C_{k+1} = b_out.
    """
    n_updates, d = truth.n_updates, truth.state_dim
    mean, own, next_ = np.empty((n_updates, d)), np.empty((n_updates, d, d)), np.empty((n_updates - 1, d, d))
    y, cov, cross = truth.x0_mean, truth.x0_factor @ truth.x0_factor.T, np.zeros(d)
    noise = truth.noise_factor @ truth.noise_factor.T
    b_in, b_out = truth.boundary_in, truth.boundary_out
    for k in range(n_updates):
        a = truth.transitions[k]
        y = a @ y
        ac = np.outer(a @ cross, b_in)
        cov = a @ cov @ a.T + noise + np.outer(b_in, b_in) + np.outer(b_out, b_out) + ac + ac.T
        cross = b_out
        mean[k], own[k] = y + truth.model_error[k], cov
        if k + 1 < n_updates:
            a_next = truth.transitions[k + 1]
            next_[k] = cov @ a_next.T + np.outer(cross, b_in)
    return mean, own, next_


@pytest.mark.parametrize("name", sorted(CONFIGS))
def test_exact_sampler_moments_equal_dense_oracle(name):
    """No sampling error: the update-rate truth's own mean and covariances are the per-sample truth's."""
    mean, cov, _ = _dense_moments(name)
    e_mean, e_own, e_next = _update_rate_moments(accel_gps_truth(_scenario(name)))
    k = mean.shape[0]
    blocks = cov.reshape(k, 3, k, 3)
    own = np.stack([blocks[i, :, i] for i in range(k)])
    nxt = np.stack([blocks[i, :, i + 1] for i in range(k - 1)])
    scale = np.sqrt(np.einsum("kii->ki", own))
    # correlations to 1e-9: rounding. The truth of 9c72f6e, which left the bias noise's share out of the
    # trapezoid's dp and dv, had variances off by up to 3.7% (trapezoid-walk-m2) and 2.8%
    # (trapezoid-markov-m2), and normalized covariances by up to 0.086 (trapezoid-markov-m2)
    pairs = (("Cov(x_k)", e_own, own, scale, scale), ("Cov(x_k, x_k+1)", e_next, nxt, scale[:-1], scale[1:]))
    for what, got, want, rows, cols in pairs:
        norm = rows[:, :, None] * cols[:, None, :]
        np.testing.assert_allclose(got / norm, want / norm, rtol=0, atol=1e-9, err_msg=f"{name}: {what}")
    np.testing.assert_allclose(e_mean, mean, rtol=0, atol=1e-9 * (1 + np.abs(mean).max()))


@pytest.mark.parametrize("integration", ["euler", "trapezoid"])
def test_model_error_is_zero_for_discrete_truth(integration):
    scenario = build_scenario("accel-gps", assignments=["scenario.truth=discrete", f"scenario.integration={integration}"])
    error = accel_gps_model_error(scenario)
    assert error.shape == (150, 3)
    np.testing.assert_array_equal(error, 0.0)
    np.testing.assert_array_equal(accel_gps_truth(scenario).model_error, 0.0)


def test_euler_velocity_model_error_is_half_a_sample_of_acceleration():
    """Euler-Maclaurin for the rectangle rule: int_0^t a - dt sum a_j = dt/2 (a(t) - a(0)) - dt^2/12 (a'(t) - a'(0)) + O(dt^4).

    So the velocity error at the fixes is A dt / 2 sin(omega t) to within A omega dt^2 / 6, of order
    A dt / 2 = 0.025 m/s for the report.
    """
    scenario = build_scenario("accel-gps")  # the default: Euler against the analytic truth
    amplitude, omega = scenario.truth.accel_amplitude, scenario.truth.accel_frequency
    dt = scenario.scenario.sample_period
    t = scenario.scenario.update_times()
    dv = accel_gps_model_error(scenario)[:, 1]
    # Rounding of a sum of J terms of size <= A dt, carried to the values' size (~A / omega).
    rounding = scenario.scenario.n_samples * np.finfo(float).eps * amplitude / omega * 2
    second_order = amplitude * omega * dt**2 / 6
    assert np.all(np.abs(dv - dt / 2 * amplitude * np.sin(omega * t)) <= second_order + rounding)
    # The two-term expansion leaves only O(dt^4 A omega^3).
    two_term = dt / 2 * amplitude * np.sin(omega * t) - dt**2 / 12 * (amplitude * omega * np.cos(omega * t) - amplitude * omega)
    fourth_order = dt**4 * amplitude * omega**3 / 360
    assert np.all(np.abs(dv - two_term) <= fourth_order + rounding)
    # Its largest value over 30 s (sin reaches 1 near t = 15.7 s) is A dt / 2.
    assert 0.999 * amplitude * dt / 2 <= np.max(np.abs(dv)) <= amplitude * dt / 2 + second_order
    # Position: the half-sample lag integrates to dt/2 v(t), up to O(dt^2) terms of size A or A omega t.
    dp = accel_gps_model_error(scenario)[:, 0]
    _, v_motion = _report_motion(t, amplitude, omega)
    assert np.all(np.abs(dp - dt / 2 * v_motion) <= dt**2 * (amplitude + amplitude * omega * t))


def test_trapezoid_model_error_is_second_order():
    scenario = build_scenario("accel-gps", assignments=["scenario.integration=trapezoid"])
    amplitude, omega = scenario.truth.accel_amplitude, scenario.truth.accel_frequency
    dt = scenario.scenario.sample_period
    t = scenario.scenario.update_times()
    error = accel_gps_model_error(scenario)
    rounding = scenario.scenario.n_samples * np.finfo(float).eps * amplitude / omega * 2
    # Trapezoid rule: int a - T = -dt^2/12 (a'(t) - a'(0)) + O(dt^4).
    expected_dv = -(dt**2) / 12 * (amplitude * omega * np.cos(omega * t) - amplitude * omega)
    assert np.all(np.abs(error[:, 1] - expected_dv) <= dt**4 * amplitude * omega**3 / 360 + rounding)
    assert np.max(np.abs(error[:, 1])) <= amplitude * omega * dt**2 / 6 + rounding
    assert np.max(np.abs(error[:, 0])) <= dt**2 * (amplitude + amplitude * omega * t.max())


# --------------------------------------------------------------------------------------------------
# the update-rate truth's matrices


def test_euler_exact_noise_covariance_is_the_truth_models_q_m():
    scenario = build_scenario("accel-gps")
    truth = accel_gps_truth(scenario)
    model = scenario.truth_model()
    phi_m, q_m = interval_transition(model.phi, model.gamma, model.w, model.steps_per_update)
    assert not truth.shares_boundary
    np.testing.assert_array_equal(truth.boundary_in, 0.0)
    np.testing.assert_array_equal(truth.boundary_out, 0.0)
    np.testing.assert_allclose(truth.transitions, np.broadcast_to(phi_m, truth.transitions.shape), rtol=1e-14, atol=1e-16)
    lq = truth.noise_factor @ truth.noise_factor.T
    np.testing.assert_allclose(lq, q_m, rtol=1e-10, atol=1e-10 * np.abs(q_m).max())
    np.testing.assert_allclose(truth.x0_factor @ truth.x0_factor.T, model.m0, rtol=1e-12)
    np.testing.assert_allclose(truth.measurement_factor @ truth.measurement_factor.T, model.v, rtol=1e-12)
    # Rank 2 (the bias gets no noise): two normals per interval, plus 2 for the fix and 3 at the start.
    assert truth.noise_factor.shape == (3, 2)
    assert truth.normals_per_realization == 3 + 150 * (2 + 2)


def test_trapezoid_exact_noise_splits_the_interval_covariance():
    """L L^T + b_in b_in^T + b_out b_out^T is the whole interval's sigma^2 sum_i C_i C_i^T."""
    scenario = build_scenario("accel-gps", assignments=["scenario.integration=trapezoid"])
    truth = accel_gps_truth(scenario)
    s, sigma = scenario.scenario, scenario.truth.accel_noise_std
    m, dt = s.steps_per_update, s.sample_period
    i = np.arange(m + 1)
    # Closed-form trapezoid weights (see tests/filters/test_mechanization.py).
    cp = (i >= 1) * (dt**2 / 6 + (m - i) * dt**2 / 2) + (i < m) * (dt**2 / 3 + (m - 1 - i) * dt**2 / 2)
    cv = np.where((i == 0) | (i == m), dt / 2, dt)
    c = -sigma * np.stack([cp, cv, np.zeros(m + 1)], axis=1)
    assert truth.shares_boundary
    np.testing.assert_allclose(truth.boundary_in, c[0], rtol=1e-12)
    np.testing.assert_allclose(truth.boundary_out, c[m], rtol=1e-12)
    total = (
        truth.noise_factor @ truth.noise_factor.T
        + np.outer(truth.boundary_in, truth.boundary_in)
        + np.outer(truth.boundary_out, truth.boundary_out)
    )
    np.testing.assert_allclose(total, c.T @ c, rtol=1e-10, atol=1e-10 * np.abs(c.T @ c).max())
    assert truth.normals_per_realization == 3 + 1 + 150 * (2 + 1 + 2)


def test_interval_weights_used_by_exact_sampler_match_mechanization():
    scenario = build_scenario("accel-gps", assignments=["scenario.integration=trapezoid"])
    truth = accel_gps_truth(scenario)
    weights = interval_weights("trapezoid", scenario.scenario.sample_period, scenario.scenario.steps_per_update)
    np.testing.assert_allclose(truth.boundary_out[:2], -scenario.truth.accel_noise_std * weights[-1], rtol=1e-14)


def test_sample_exact_is_reproducible():
    truth = accel_gps_truth(build_scenario("accel-gps", assignments=["scenario.integration=trapezoid"]))
    a = sample_exact(truth, np.random.default_rng(3), 4)
    b = sample_exact(truth, np.random.default_rng(3), 4)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    assert a[0].shape == (4, 150, 3) and a[1].shape == (4, 150, 2)


def test_truth_from_model_samples_the_linear_gaussian_model():
    """Generic model: states follow P_{k} = Phi_m P_{k-1} Phi_m^T + Q_m from M0, z = H x + v."""
    model = LinearGaussianModel(
        phi=[[0.95, 0.1, 0.0], [0.0, 0.9, 0.2], [0.0, 0.0, 1.0]],
        gamma=[[0.0, 0.1], [1.0, 0.0], [0.0, 0.3]],
        h=[[1.0, 0.0, 0.5], [0.0, 1.0, 0.0]],
        w=[[0.2, 0.05], [0.05, 0.1]],
        v=[[0.5, 0.1], [0.1, 0.3]],
        x0=[1.0, -1.0, 0.5],
        m0=[[1.0, 0.2, 0.0], [0.2, 0.5, 0.0], [0.0, 0.0, 0.3]],
        steps_per_update=3,
        sample_period=0.1,
    )
    n_updates = 4
    states, meas = sample_exact(truth_from_model(model, n_updates), np.random.default_rng(12), N)
    phi_m, q_m = interval_transition(model.phi, model.gamma, model.w, model.steps_per_update)
    # Dense joint moments of (x_0 .. x_{K-1}) by the recursion on means and cross-covariances.
    means, covs = [], {}
    mu, p = model.x0, model.m0
    for k in range(n_updates):
        mu, p = phi_m @ mu, phi_m @ p @ phi_m.T + q_m
        means.append(mu)
        covs[k, k] = p
    for k in range(n_updates):
        for j in range(k + 1, n_updates):
            covs[j, k] = np.linalg.matrix_power(phi_m, j - k) @ covs[k, k]
            covs[k, j] = covs[j, k].T
    h, v = model.h, model.v
    for k in (0, n_updates - 2):
        c6 = np.block([[covs[k, k], covs[k, k + 1]], [covs[k + 1, k], covs[k + 1, k + 1]]])
        hb = np.kron(np.eye(2), h)
        full = np.block([[c6, c6 @ hb.T], [hb @ c6, hb @ c6 @ hb.T + np.kron(np.eye(2), v)]])
        mu6 = np.concatenate([means[k], means[k + 1]])
        assert_gaussian_moments(_stack(states, meas, k), np.concatenate([mu6, hb @ mu6]), full, what=f"update {k}")


def test_truth_from_model_adds_model_error():
    model = build_scenario("accel-gps", assignments=["scenario.duration=1"]).truth_model()
    error = np.arange(15.0).reshape(5, 3)
    plain = sample_exact(truth_from_model(model, 5), np.random.default_rng(1), 3)
    shifted = sample_exact(truth_from_model(model, 5, error), np.random.default_rng(1), 3)
    np.testing.assert_allclose(shifted[0] - plain[0], np.broadcast_to(error, (3, 5, 3)), rtol=0, atol=1e-12)
    np.testing.assert_allclose(shifted[1] - plain[1], np.broadcast_to(error[:, :2], (3, 5, 2)), rtol=0, atol=1e-12)
