"""The gain schedule (interval matrices, covariance pass, run with gains) against independent oracles.

Oracles: a plain per-sample Riccati recursion written here, the reference steps run one update at a
time, and the degenerate filter with H = 0.
"""

from __future__ import annotations

import numpy as np
import pytest

from kalcal.core.model import LinearGaussianModel
from kalcal.core.steps import covariance_pass, interval_transition, predict, update
from kalcal.filters.gains import run_with_gains
from kalcal.scenarios.accel_gps.settings import AccelGpsScenario
from kalcal.scenarios import build_scenario
from tests._helpers import assert_close, cov_atol
from tests.core._models import blind_model


def _reference_riccati(model: LinearGaussianModel, n_updates: int):
    """Per-sample recursion of the report: m propagations, then the Joseph update, K times."""
    phi, q = model.phi, model.gamma @ model.w @ model.gamma.T
    h, v = model.h, model.v
    eye = np.eye(model.state_dim)
    cov = model.m0.copy()
    priors, posteriors, gains = [], [], []
    for _ in range(n_updates):
        for _ in range(model.steps_per_update):
            cov = phi @ cov @ phi.T + q
        priors.append(cov)
        gain = cov @ h.T @ np.linalg.inv(h @ cov @ h.T + v)
        i_kh = eye - gain @ h
        cov = i_kh @ cov @ i_kh.T + gain @ v @ gain.T
        gains.append(gain)
        posteriors.append(cov)
    return np.array(priors), np.array(posteriors), np.array(gains)


def _random_model(rng: np.random.Generator, d=3, p=2, q=2, steps=3) -> LinearGaussianModel:
    """A small well-conditioned model: stable Phi, positive definite W, V, M0."""
    a = rng.standard_normal((d, d))
    phi = 0.9 * a / np.max(np.abs(np.linalg.eigvals(a)))
    b = rng.standard_normal((q, q))
    c = rng.standard_normal((p, p))
    e = rng.standard_normal((d, d))
    return LinearGaussianModel(
        phi=phi,
        gamma=rng.standard_normal((d, q)),
        h=rng.standard_normal((p, d)),
        w=b @ b.T + 0.5 * np.eye(q),
        v=c @ c.T + 0.5 * np.eye(p),
        x0=rng.standard_normal(d),
        m0=e @ e.T + np.eye(d),
        steps_per_update=steps,
        sample_period=0.1,
    )


@pytest.fixture(scope="module")
def scenario() -> AccelGpsScenario:
    # The report's scenario: 150 fixes, 6000 accelerometer samples.
    return build_scenario("accel-gps")


# --------------------------------------------------------------------------------------------------
# covariance_pass


@pytest.mark.parametrize("which", ["accel-gps", "random"])
def test_covariance_pass_matches_per_sample_recursion(which, scenario):
    model = scenario.filter_model() if which == "accel-gps" else _random_model(np.random.default_rng(3))
    n_updates = 50
    prior, posterior, gains = _reference_riccati(model, n_updates)
    schedule = covariance_pass(model, n_updates)
    assert schedule.prior_cov.shape == (n_updates, model.state_dim, model.state_dim)
    assert schedule.gain.shape == (n_updates, model.state_dim, model.measurement_dim)
    np.testing.assert_allclose(schedule.prior_cov, prior, rtol=1e-12, atol=0)
    assert_close(schedule.posterior_cov, posterior, atol=cov_atol(posterior, 1e-12), what="P")
    # Gains: entries scale with the state and measurement units; compare column by column.
    gain_scale = np.max(np.abs(gains), axis=(0, 1), keepdims=True)
    assert_close(schedule.gain, gains, atol=1e-12 * gain_scale, what="K")
    s_ref = model.h @ prior @ model.h.T + model.v
    np.testing.assert_allclose(schedule.innovation_cov, s_ref, rtol=1e-12)


def test_covariance_pass_interval_matrices(scenario):
    model = scenario.filter_model()
    schedule = covariance_pass(model, 2)
    phi_m, q_m = interval_transition(model.phi, model.gamma, model.w, model.steps_per_update)
    np.testing.assert_array_equal(schedule.phi_interval, phi_m)
    np.testing.assert_array_equal(schedule.q_interval, q_m)


def test_covariance_pass_is_symmetric_and_shrinks_on_update(scenario):
    schedule = covariance_pass(scenario.filter_model(), 50)
    np.testing.assert_array_equal(schedule.posterior_cov, np.swapaxes(schedule.posterior_cov, 1, 2))
    # A measurement can only remove variance: M - P is positive semi-definite.
    shrink = np.linalg.eigvalsh(schedule.prior_cov - schedule.posterior_cov)
    assert np.all(shrink > -1e-12 * np.abs(schedule.prior_cov).max())


def test_joseph_and_standard_forms_agree_on_well_conditioned_problem():
    model = _random_model(np.random.default_rng(11))
    joseph = covariance_pass(model, 30, form="joseph")
    standard = covariance_pass(model, 30, form="standard")
    np.testing.assert_allclose(standard.posterior_cov, joseph.posterior_cov, rtol=1e-9, atol=0)
    np.testing.assert_allclose(standard.gain, joseph.gain, rtol=1e-9, atol=0)


# --------------------------------------------------------------------------------------------------
# run_with_gains


def test_run_with_gains_equals_predict_update_loop():
    rng = np.random.default_rng(5)
    model = _random_model(rng)
    n, n_updates = 4, 12
    z = rng.standard_normal((n, n_updates, model.measurement_dim))
    x0 = rng.standard_normal((n, model.state_dim))
    schedule = covariance_pass(model, n_updates)
    run = run_with_gains(schedule, model.h, z, x0)
    assert run.prior.shape == (n, n_updates, model.state_dim)
    assert run.residual.shape == (n, n_updates, model.measurement_dim)
    for i in range(n):
        x, cov = x0[i], model.m0
        for k in range(n_updates):
            x, cov = predict(x, cov, schedule.phi_interval, schedule.q_interval)
            np.testing.assert_allclose(run.prior[i, k], x, rtol=1e-12, atol=1e-12)
            result = update(x, cov, z[i, k], model.h, model.v)
            x, cov = result.x, result.cov
            np.testing.assert_allclose(run.residual[i, k], result.residual, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(run.posterior[i, k], x, rtol=1e-12, atol=1e-12)


def test_run_with_gains_shared_prior_mean_broadcasts():
    rng = np.random.default_rng(6)
    model = _random_model(rng)
    z = rng.standard_normal((3, 5, model.measurement_dim))
    schedule = covariance_pass(model, 5)
    shared = run_with_gains(schedule, model.h, z, model.x0)
    tiled = run_with_gains(schedule, model.h, z, np.tile(model.x0, (3, 1)))
    np.testing.assert_array_equal(shared.posterior, tiled.posterior)


# --------------------------------------------------------------------------------------------------
# degenerate oracle: H = 0 only propagates


def test_covariance_pass_with_zero_h_only_propagates():
    model = blind_model()
    schedule = covariance_pass(model, 6)
    np.testing.assert_array_equal(schedule.gain, 0.0)
    np.testing.assert_allclose(schedule.posterior_cov, schedule.prior_cov, rtol=1e-15)
    # Open-loop propagation: P_k = Phi^{m(k+1)} M0 (.)^T + sum of the noise pushed through.
    q = model.gamma @ model.w @ model.gamma.T
    cov = model.m0.copy()
    for k in range(6):
        for _ in range(model.steps_per_update):
            cov = model.phi @ cov @ model.phi.T + q
        np.testing.assert_allclose(schedule.posterior_cov[k], cov, rtol=1e-13)
    run = run_with_gains(schedule, model.h, np.full((1, 6, 1), 7.0), model.x0)
    expected = [np.linalg.matrix_power(model.phi, model.steps_per_update * (k + 1)) @ model.x0 for k in range(6)]
    np.testing.assert_allclose(run.posterior[0], expected, rtol=1e-14)


# --------------------------------------------------------------------------------------------------
# interval_transition


@pytest.mark.parametrize("steps", [0, 1, 2, 7, 40])
def test_interval_transition_equals_repeated_single_steps(steps):
    rng = np.random.default_rng(9)
    model = _random_model(rng, d=3, q=2)
    phi_m, q_m = interval_transition(model.phi, model.gamma, model.w, steps)
    np.testing.assert_allclose(phi_m, np.linalg.matrix_power(model.phi, steps), rtol=1e-12, atol=1e-15)
    # Q_m = sum_i Phi^i Gamma W Gamma^T Phi^i^T, written as an explicit sum of matrix powers.
    step_noise = model.gamma @ model.w @ model.gamma.T
    powers = [np.linalg.matrix_power(model.phi, i) for i in range(steps)]
    q_ref = sum((pw @ step_noise @ pw.T for pw in powers), np.zeros((3, 3)))
    np.testing.assert_allclose(q_m, q_ref, rtol=1e-12, atol=1e-15)
    # Propagating any covariance sample by sample equals one interval step.
    cov = model.m0.copy()
    x = model.x0.copy()
    for _ in range(steps):
        x, cov = predict(x, cov, model.phi, step_noise)
    x_m, cov_m = predict(model.x0, model.m0, phi_m, q_m)
    np.testing.assert_allclose(x_m, x, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(cov_m, cov, rtol=1e-12, atol=1e-14)


def test_interval_transition_of_accel_gps_model_closed_form(scenario):
    """Phi^m of the report's model, and its Q_m from the weights of the m noise samples."""
    model = scenario.filter_model()
    m, dt = model.steps_per_update, model.sample_period
    phi_m, q_m = interval_transition(model.phi, model.gamma, model.w, m)
    t = m * dt
    np.testing.assert_allclose(phi_m, [[1, t, -t * t / 2], [0, 1, -t], [0, 0, 1]], rtol=1e-12, atol=1e-15)
    # Sample i of the interval adds sigma^2 c_i c_i^T with c_i = [dt^2/2 + (m - 1 - i) dt^2, dt, 0].
    i = np.arange(m)
    c = np.stack([dt * dt / 2 + (m - 1 - i) * dt * dt, np.full(m, dt), np.zeros(m)], axis=1)
    np.testing.assert_allclose(q_m, model.w[0, 0] * c.T @ c, rtol=1e-12, atol=1e-20)


@pytest.mark.parametrize("missing", [np.nan, np.inf])
def test_run_with_gains_refuses_a_missing_measurement(missing):
    model = blind_model()
    schedule = covariance_pass(model, 4)
    z = np.ones((3, 4, 1))
    z[2, 1, 0] = missing
    with pytest.raises(ValueError, match="realization 2 at update 1 is not finite"):
        run_with_gains(schedule, model.h, z, model.x0)
