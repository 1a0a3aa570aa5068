"""The exact covariance analysis against independent oracles.

* the plain Riccati P of the filter's own covariance pass, for a correct filter (the truth is the
  filter's model, so P_true = P);
* the dense joint Gaussian of every fix: a run of the exact sampler and of the gain recursion is affine
  in its standard normals, so feeding them the identity (one column per normal) gives the whole stacked
  linear map from every noise source to every state, estimate and innovation, whose covariances are
  closed-form matrices. Used for a mistuned, reduced-order filter (a 2-state filter against a 3-state
  truth with a Gauss-Markov measurement error) with a shared boundary sample, a prior-mean offset and
  deterministic model error, and for the accel-gps truth with the trapezoid rule and a drifting bias.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from kalcal.analysis.fixed_gain import analyze_problem, analyze_scenario, truth_arrays
from kalcal.core.lincov import FilterArrays, mean_normalized_square, propagate
from kalcal.core.model import LinearGaussianModel
from kalcal.core.steps import covariance_pass
from kalcal.errors import KalcalError
from kalcal.filters.gains import run_with_gains
from kalcal.scenarios.model_file.model import parse_model
from kalcal.scenarios import build_scenario
from kalcal.montecarlo.scenarios import build_problem
from kalcal.simulation.exact import UpdateRateTruth, sample_exact, truth_from_model
from tests._helpers import assert_close, cov_atol


class _Basis:
    """A stand-in generator whose standard normals are the identity: column i is the i-th normal set to 1."""

    def __init__(self, first: int, per_update: int, n_updates: int, scale: float):
        self.size = first + n_updates * per_update
        eye = scale * np.eye(self.size)
        self.draws = [eye[:first], eye[first:].reshape(n_updates, per_update, self.size)]

    def standard_normal(self, shape):
        out = self.draws.pop(0)
        assert out.shape == tuple(shape)
        return out


def _dense(truth: UpdateRateTruth, filt: FilterArrays, error_map=None):
    """Means and the stacked linear maps of e, xhat and r over all fixes (the dense joint Gaussian)."""
    c = int(truth.shares_boundary)
    first, per = truth.x0_factor.shape[1] + c, truth.noise_factor.shape[1] + c + truth.h.shape[0]

    def run(scale):
        states, z = sample_exact(truth, _Basis(first, per, truth.n_updates, scale), first + truth.n_updates * per)
        gains = covariance_pass_like(filt)
        out = run_with_gains(gains, filt.h, z, filt.x0)
        m = np.eye(states.shape[-1]) if error_map is None else error_map
        return states @ m.T - out.posterior, out.posterior, out.residual  # (n, K, .)

    mean = [a[0] for a in run(0.0)]
    maps = [a - mu for a, mu in zip(run(1.0), mean)]
    return mean, maps


def covariance_pass_like(filt: FilterArrays):
    """A gain schedule holding the filter's own gains and transitions (for run_with_gains)."""
    from kalcal.core.steps import GainSchedule

    k, d, _ = filt.transitions.shape
    empty = np.zeros((k, d, d))
    return GainSchedule(empty, empty, filt.gain, np.zeros((k,) + (filt.h.shape[0],) * 2), filt.transitions[0], empty[0], filt.transitions)


def _assert_equals_dense(truth, filt, error_map, rtol):
    moments = propagate(truth_arrays(truth), filt, error_map)
    (e0, x0, r0), (e, x, r) = _dense(truth, filt, error_map)
    cov_e = np.einsum("nka,nkb->kab", e, e)
    assert_close(moments.mean_error, e0, atol=rtol * np.sqrt(np.diagonal(cov_e, axis1=1, axis2=2)), what="mean error")
    assert_close(moments.error_cov, cov_e, rtol=rtol, atol=cov_atol(cov_e, rtol), what="error covariance")
    cross = np.einsum("nka,nkb->kab", e, x) + e0[:, :, None] * x0[:, None, :]
    scale = np.sqrt(np.einsum("nka,nka->ka", e, e)[:, :, None] * np.einsum("nka,nka->ka", x, x)[:, None, :] + 1.0)
    assert_close(moments.mean_estimate, x0, rtol=rtol, atol=rtol, what="mean estimate")
    assert_close(moments.error_estimate, cross, atol=rtol * (scale + np.abs(cross)), what="E[e xhat^T]")
    cov_x = np.einsum("nka,nkb->kab", x, x)
    assert_close(moments.estimate_cov, cov_x, rtol=rtol, atol=cov_atol(cov_x, rtol), what="Cov(xhat)")
    pairs = np.einsum("nka,njb->kajb", r, r) + np.einsum("ka,jb->kajb", r0, r0)
    own = np.sqrt(np.einsum("kaka->ka", pairs))
    assert_close(moments.mean_residual, r0, atol=rtol * own, what="mean residual")
    assert_close(moments.residual_second_moment, pairs, atol=rtol * own[:, :, None, None] * own[None, None], what="E[r_k r_j^T]")
    return moments, (e0, e, r0, r)


def _reduced_order_case():
    """A 2-state filter (position, velocity) against a 3-state truth whose position fix carries a
    Gauss-Markov error c: z = p + c + eta. The filter ignores c, its noise settings are off, its prior
    mean differs, the truth shares a boundary sample between intervals and has model error."""
    dt, m, k = 0.1, 5, 12
    phi2 = np.array([[1.0, dt], [0.0, 1.0]])
    filter_model = LinearGaussianModel(
        phi=phi2, gamma=np.array([[0.5 * dt * dt], [dt]]), h=np.array([[1.0, 0.0], [0.0, 1.0]]),
        w=np.array([[0.09]]), v=np.diag([2.0, 0.05]), x0=np.array([0.3, -0.1]), m0=np.diag([4.0, 0.5]),
        steps_per_update=m, sample_period=dt,
    )  # fmt: skip
    phi3 = np.zeros((3, 3))
    phi3[:2, :2] = phi2
    phi3[2, 2] = np.exp(-dt / 2.0)
    truth_model = LinearGaussianModel(
        phi=phi3, gamma=np.array([[0.5 * dt * dt, 0.0], [dt, 0.0], [0.0, 1.0]]), h=np.array([[1.0, 0.0, 1.0], [0.0, 1.0, 0.0]]),
        w=np.diag([0.25, 0.3**2 * (1 - np.exp(-2 * dt / 2.0))]), v=np.diag([1.0, 0.1]), x0=np.array([1.0, 0.5, 0.0]),
        m0=np.array([[9.0, 0.5, 0.0], [0.5, 1.0, 0.0], [0.0, 0.0, 0.09]]), steps_per_update=m, sample_period=dt,
    )  # fmt: skip
    rng = np.random.default_rng(3)
    base = truth_from_model(truth_model, k, model_error=0.05 * rng.standard_normal((k, 3)))
    truth = dataclasses.replace(base, boundary_in=np.array([0.02, 0.1, 0.0]), boundary_out=np.array([0.01, 0.05, 0.0]))
    schedule = covariance_pass(filter_model, k)
    filt = FilterArrays(schedule.transitions, filter_model.h, schedule.gain, filter_model.x0)
    return truth, filt, np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), schedule


def test_reduced_order_mistuned_filter_equals_dense_joint_gaussian():
    truth, filt, error_map, schedule = _reduced_order_case()
    moments, (e0, e, r0, r) = _assert_equals_dense(truth, filt, error_map, 1e-9)
    # the mean NEES and NIS under the truth: E[v^T W v] of the dense maps
    p_inv = np.linalg.inv(schedule.posterior_cov)
    s_inv = np.linalg.inv(schedule.innovation_cov)
    nees = np.einsum("nka,kab,nkb->k", e, p_inv, e) + np.einsum("ka,kab,kb->k", e0, p_inv, e0)
    nis = np.einsum("nka,kab,nkb->k", r, s_inv, r) + np.einsum("ka,kab,kb->k", r0, s_inv, r0)
    assert_close(mean_normalized_square(p_inv, moments.mean_error, moments.error_cov), nees, rtol=1e-9, what="NEES")
    assert_close(mean_normalized_square(s_inv, moments.mean_residual, moments.residual_cov), nis, rtol=1e-9, what="NIS")
    # the filter is far from the truth here: P_true is not P
    assert np.max(np.abs(moments.error_cov - schedule.posterior_cov) / schedule.posterior_cov) > 0.1


def test_accel_gps_trapezoid_drifting_bias_equals_dense_joint_gaussian():
    scenario = build_scenario(
        "accel-gps",
        assignments=["scenario.integration=trapezoid", "scenario.duration=4", "truth.bias_walk_std=2e-3", "truth.accel_noise_std=0.05"],
    )
    problem, _ = build_problem(scenario)
    assert problem.truth.shares_boundary
    filt = FilterArrays(problem.schedule.transitions, problem.filter_model.h, problem.schedule.gain, problem.filter_model.x0)
    _assert_equals_dense(problem.truth, filt, None, 1e-9)


@pytest.mark.parametrize(
    "assignments",
    [[], ["scenario.truth=discrete"], ["truth.bias_correlation_time=20"], ["truth.scale_std=1e-3"], ["truth.bias_walk_std=2e-4"]],
)
def test_correct_filter_error_covariance_is_the_riccati_p(assignments):
    """With the filter's model the truth's, P_true = P (centered: the model error moves only the mean),
    and the mean error is the filter's response to the truth's mean trajectory."""
    scenario = build_scenario("accel-gps", assignments=assignments)
    problem, _ = build_problem(scenario)
    result = analyze_problem(problem, pairs=False)
    p = problem.schedule.posterior_cov
    assert_close(result.moments.error_cov, p, rtol=1e-10, atol=cov_atol(p, 1e-10), what="P_true")
    sigma = np.sqrt(np.diagonal(p, axis1=1, axis2=2))
    assert_close(result.moments.mean_error, problem.expected_mean_error(), atol=1e-10 * sigma, what="mean error")
    # mean NEES = d + |mean error|^2 in P's metric
    m = result.moments.mean_error
    assert_close(result.mean_nees, p.shape[-1] + np.einsum("ka,kab,kb->k", m, np.linalg.inv(p), m), rtol=1e-9, what="NEES")


def test_correct_model_file_error_covariance_is_the_riccati_p():
    text = """
steps_per_update = 4
updates = 25
phi = [[1.0, 0.1], [0.0, 0.95]]
gamma = [[0.005], [0.1]]
h = [[1.0, 0.0]]
w = [[0.04]]
v = [[4.0]]
x0 = [0.0, 10.0]
m0 = [[25.0, 0.0], [0.0, 1.0]]
"""
    scenario = parse_model(text, "cv.toml")
    result = analyze_scenario(scenario)
    p = covariance_pass(scenario.filter, 25).posterior_cov
    assert_close(result.moments.error_cov, p, rtol=1e-10, atol=cov_atol(p, 1e-10), what="P_true")
    assert_close(result.moments.mean_error, np.zeros((25, 2)), atol=1e-12, what="mean error")
    assert_close(result.mean_nees, np.full(25, 2.0), rtol=1e-10, what="NEES")
    assert_close(result.mean_nis, np.full(25, 1.0), rtol=1e-10, what="NIS")


def test_scale_bias_is_refused_in_one_line():
    with pytest.raises(KalcalError, match="scale-bias: no exact covariance analysis") as info:
        analyze_scenario(build_scenario("scale-bias"))
    assert "\n" not in str(info.value)
