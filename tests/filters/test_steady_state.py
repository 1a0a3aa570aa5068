"""The steady state from the DARE against closed forms, the long Riccati recursion, and honest failures.

Oracles: the scalar random walk measured directly, whose steady prior variance solves a quadratic;
the time-varying covariance pass run long enough to settle; the DARE's own residual. Cases without a
stabilizing solution: the accel-gps default (a constant bias that no noise reaches) and a model whose
measurements see nothing.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import scipy.linalg

from kalcal.core.model import LinearGaussianModel
from kalcal.core.steps import covariance_pass, interval_transition
from kalcal.filters.steady_state import convergence, model_steady_state_view, no_steady_state, steady_state
from kalcal.scenarios import build_scenario
from tests._helpers import assert_close, cov_atol

NAMES = ("position", "velocity", "bias")


def _tracker(dt=0.5, steps=2) -> LinearGaussianModel:
    """A constant-velocity tracker with position fixes: white acceleration noise, 1 m fixes."""
    return LinearGaussianModel(
        phi=[[1.0, dt], [0.0, 1.0]],
        gamma=[[0.5 * dt * dt], [dt]],
        h=[[1.0, 0.0]],
        w=[[0.04]],
        v=[[1.0]],
        x0=[0.0, 0.0],
        m0=[[100.0, 0.0], [0.0, 25.0]],
        steps_per_update=steps,
        sample_period=dt,
    )


def _accel_gps_with_bias_walk(walk_variance=1e-10) -> LinearGaussianModel:
    """The accel-gps filter model with a random-walk input on the bias, built here by hand."""
    model = build_scenario("accel-gps").filter_model()
    return dataclasses.replace(
        model,
        gamma=np.hstack([model.gamma, [[0.0], [0.0], [1.0]]]),
        w=np.diag([model.w[0, 0], walk_variance]),
    )


def test_scalar_random_walk_matches_the_closed_form():
    q, v = 0.3, 2.0
    model = LinearGaussianModel(phi=[[1.0]], gamma=[[1.0]], h=[[1.0]], w=[[q]], v=[[v]], x0=[0.0], m0=[[5.0]])
    result = steady_state(model)
    # M = M - M^2 / (M + v) + q  <=>  M^2 - q M - q v = 0
    m = (q + np.sqrt(q * q + 4 * q * v)) / 2
    assert result.exists and result.reason == ""
    np.testing.assert_allclose(result.prior_cov, [[m]], rtol=1e-12)
    np.testing.assert_allclose(result.gain, [[m / (m + v)]], rtol=1e-12)
    np.testing.assert_allclose(result.posterior_cov, [[m * v / (m + v)]], rtol=1e-12)
    np.testing.assert_allclose(result.innovation_cov, [[m + v]], rtol=1e-12)
    np.testing.assert_allclose(result.spectral_radius, v / (m + v), rtol=1e-12)


@pytest.mark.parametrize("which", ["tracker", "accel-gps with a bias walk"])
def test_steady_state_is_where_the_riccati_recursion_settles(which):
    model = _tracker() if which == "tracker" else _accel_gps_with_bias_walk()
    result = steady_state(model, NAMES)
    assert result.exists and result.stabilizing and result.spectral_radius < 1
    phi, q = interval_transition(model.phi, model.gamma, model.w, model.steps_per_update)
    m = result.prior_cov
    # The DARE itself: M = Phi (M - M H^T S^-1 H M) Phi^T + Q, i.e. M = Phi P Phi^T + Q.
    assert_close(phi @ result.posterior_cov @ phi.T + q, m, atol=cov_atol(m, 1e-10), what="DARE residual")
    schedule = covariance_pass(model, 3000)
    assert_close(schedule.prior_cov[-1], m, atol=cov_atol(m, 1e-9), what="M_K vs M_inf")
    assert_close(schedule.posterior_cov[-1], result.posterior_cov, atol=cov_atol(result.posterior_cov, 1e-9), what="P")
    scale = np.abs(schedule.gain[-1]).max(axis=0, keepdims=True)
    assert_close(result.gain, schedule.gain[-1], atol=1e-9 * scale, what="K")

    progress = convergence(schedule.posterior_cov, result.posterior_cov)
    k = progress.update
    assert k is not None and 0 < k < 3000
    assert np.all(progress.relative_gap[k:] < 1e-3) and progress.relative_gap[k - 1] >= 1e-3
    for i, k_i in enumerate(progress.state_update):
        assert k_i is not None and np.all(progress.state_gap[k_i:, i] < 1e-3)


def test_bias_walk_setting_of_the_scenario_has_a_steady_state():
    """The same through the scenario's own setting, where it exists (filter.bias_walk_std)."""
    scenario = build_scenario("accel-gps", assignments=["filter.bias_walk_std=1e-5"])
    result = steady_state(scenario.filter_model(), NAMES)
    assert result.exists, result.reason
    assert result.posterior_cov[2, 2] > 0


def test_accel_gps_default_has_no_stabilizing_solution_and_says_why():
    model = build_scenario("accel-gps").filter_model()
    result = steady_state(model, NAMES)
    assert not result.exists and not result.stabilizing
    assert "not stabilizable" in result.reason and "eigenvalue 1 (mostly bias)" in result.reason
    if result.posterior_cov is not None:
        # scipy's answer is the limit with a perfectly known bias: the closed loop keeps the bias mode at 1.
        assert result.posterior_cov[2, 2] == pytest.approx(0.0, abs=1e-15)
        assert result.spectral_radius == pytest.approx(1.0, abs=1e-9)
    # ... and the time-varying filter keeps shrinking the bias variance, towards 1/k (k P_k,bb settles).
    schedule = covariance_pass(model, 10_000)
    bias = schedule.posterior_cov[:, 2, 2]
    assert np.all(np.diff(bias[10:]) < 0)
    assert bias[9_999] * 10_000 == pytest.approx(bias[4_999] * 5_000, rel=0.02)


def test_a_mode_the_measurements_never_see_is_not_detectable():
    model = LinearGaussianModel(
        phi=[[1.0, 0.5], [0.0, 1.0]], gamma=[[0.125], [0.5]], h=np.zeros((1, 2)), w=[[0.2]], v=[[1.0]],
        x0=[0.0, 0.0], m0=np.eye(2),
    )
    result = steady_state(model, ("p", "v"))
    assert not result.exists
    assert "not detectable" in result.reason


def test_a_scipy_failure_is_reported_not_raised(monkeypatch):
    def fail(*args, **kwargs):
        raise np.linalg.LinAlgError("Failed to find a finite solution.")

    monkeypatch.setattr(scipy.linalg, "solve_discrete_are", fail)
    result = steady_state(_tracker())
    assert not result.exists and result.prior_cov is None and result.posterior_cov is None
    assert "solve_discrete_are failed: Failed to find a finite solution" in result.reason


def test_convergence_not_within_a_short_run():
    model = _tracker()
    result = steady_state(model)
    progress = convergence(covariance_pass(model, 4).posterior_cov, result.posterior_cov)
    assert progress.update is None and progress.relative_gap.shape == (4,)
    assert progress.state_update == (None, None)


def test_model_view_sets_the_steady_state_beside_the_time_varying_filter():
    model = _tracker()
    schedule = covariance_pass(model, 200)
    times = np.arange(1, 201) * 1.0
    view = model_steady_state_view(model, schedule.posterior_cov, times, ("position", "velocity"), ("m", "m/s"))
    assert view.applies and view.has_matrices and view.reason == ""
    assert dataclasses.is_dataclass(view) and view.state_units == ("m", "m/s")
    # Oracle: the plain Riccati recursion run long past the schedule reaches the same P_inf.
    phi, q = interval_transition(model.phi, model.gamma, model.w, model.steps_per_update)
    cov = model.m0
    for _ in range(5000):
        cov = phi @ cov @ phi.T + q
        gain = cov @ model.h.T @ np.linalg.inv(model.h @ cov @ model.h.T + model.v)
        cov = (np.eye(2) - gain @ model.h) @ cov
    assert_close(view.result.posterior_cov, cov, atol=cov_atol(cov, 1e-9), what="P_inf")
    k = view.convergence.update
    assert k is not None and view.converged_time() == times[k]
    gap = np.linalg.norm(schedule.posterior_cov - cov, axis=(-2, -1)) / np.linalg.norm(cov)
    assert np.all(gap[k:] < view.convergence.tolerance) and (k == 0 or gap[k - 1] >= view.convergence.tolerance)


def test_no_steady_state_view_says_why():
    view = no_steady_state("the gains depend on the data", ("a",), ("1",))
    assert not view.applies and not view.has_matrices and view.converged_time() is None
    assert view.reason == "the gains depend on the data"
