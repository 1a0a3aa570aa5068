"""A filter with fewer states than its truth ([truth] map), against the dense joint Gaussian of all errors.

The model: a 1-state random-walk filter of a quantity x measured every 2 steps, against a truth whose
fixes also carry a first-order Gauss-Markov error g (x_truth = [x, g], map = [1, 0]). Every truth state
at every step and every fix is linear in u = [x_0 - x0, w_0 .. w_{Km-1}, v_1 .. v_K] ~ N(0, D); the
filter's estimates are linear in the fixes, so the error e_k = x_k - xhat_k is a linear map of u and
its exact mean and covariance are closed-form (a plain numpy loop here, no package code).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
import scipy.stats

from kalcal.core.model import LinearGaussianModel
from kalcal.api.verification import verify
from kalcal.scenarios.model_file.model import parse_model
from kalcal.scenarios.model_file.truth import MODEL_KEYS, MappedTruthModel
from kalcal.montecarlo.accumulators import MomentSums
from kalcal.montecarlo.problem import FixedGainProblem
from kalcal.montecarlo.scenarios import build_problem
from kalcal.simulation.exact import truth_from_model
from tests._helpers import assert_close, bonferroni_k, reduced_model_text, sums_equal

N = 20_000


def _scenario(**kwargs):
    return parse_model(reduced_model_text(**kwargs), "reduced.toml")


def _gains(f, n_updates):
    """The filter's own gains by the textbook Riccati loop, one model step at a time."""
    cov, gains, posteriors = np.array(f.m0), [], []
    for _ in range(n_updates):
        for _ in range(f.steps_per_update):
            cov = f.phi @ cov @ f.phi.T + f.gamma @ f.w @ f.gamma.T
        s = f.h @ cov @ f.h.T + f.v
        gain = np.linalg.solve(s, f.h @ cov).T
        a = np.eye(cov.shape[0]) - gain @ f.h
        cov = a @ cov @ a.T + gain @ f.v @ gain.T
        gains.append(gain)
        posteriors.append(cov)
    return np.array(gains), np.array(posteriors)


def _exact_errors(scenario):
    """Exact E[e_k] (K, d) and Cov(e_k) (K, d, d) with e_k = M x_k - xhat_k, from the dense joint Gaussian."""
    t, f, error_map = scenario.truth, scenario.filter, scenario.truth_map
    n, q = t.gamma.shape
    p, m, k_count = t.h.shape[0], t.steps_per_update, scenario.model.updates
    steps = k_count * m
    size = n + steps * q + k_count * p
    cov_u = scipy.linalg.block_diag(t.m0, *[t.w] * steps, *[t.v] * k_count)
    x_map, x_mean = np.zeros((n, size)), np.array(t.x0)
    x_map[:, :n] = np.eye(n)
    states, state_means, fixes, fix_means = [], [], [], []
    for j in range(steps):
        x_map = t.phi @ x_map
        x_map[:, n + j * q : n + (j + 1) * q] += t.gamma
        x_mean = t.phi @ x_mean
        if (j + 1) % m == 0:
            k = (j + 1) // m - 1
            z = t.h @ x_map
            z[:, n + steps * q + k * p : n + steps * q + (k + 1) * p] += np.eye(p)
            states.append(x_map.copy())
            state_means.append(x_mean.copy())
            fixes.append(z)
            fix_means.append(t.h @ x_mean)
    gains, _ = _gains(f, k_count)
    phi_m = np.linalg.matrix_power(f.phi, m)
    est_map, est_mean = np.zeros((f.state_dim, size)), np.array(f.x0)
    means, covs = [], []
    for k in range(k_count):
        est_map, est_mean = phi_m @ est_map, phi_m @ est_mean
        est_map = est_map + gains[k] @ (fixes[k] - f.h @ est_map)
        est_mean = est_mean + gains[k] @ (fix_means[k] - f.h @ est_mean)
        e = error_map @ states[k] - est_map
        means.append(error_map @ state_means[k] - est_mean)
        covs.append(e @ cov_u @ e.T)
    return np.array(means), np.array(covs)


def test_the_compiled_kernel_and_the_numpy_path_agree_on_a_mapped_truth():
    problem, _ = build_problem(_scenario(gm_std=1.0))
    assert problem.truth.error_map is not None and problem.truth.state_dim == 2 and problem.truth.error_dim == 1
    compiled = problem.block_sums(np.random.default_rng(5), 300, "exact")
    reference = MomentSums.from_block(problem.run_block(np.random.default_rng(5), 300, "exact"))
    for name in reference.__dataclass_fields__:
        a, b = getattr(compiled, name), getattr(reference, name)
        if b is None:
            assert a is None, name
            continue
        scale = max(float(np.abs(b).max()), 1.0)
        assert_close(a, b, atol=1e-10 * scale, what=name)
    assert compiled.error.shape == (12, 1)


def test_an_identity_map_gives_the_unmapped_sums_bit_for_bit():
    scenario = _scenario(gm_std=0.5)
    plain = build_problem(scenario)[0]
    # the 2-state truth over a 2-state filter's own states, once without a map and once with map = I
    values = {key: getattr(scenario.truth, key) for key in (*MODEL_KEYS, "steps_per_update", "sample_period")}
    unmapped = truth_from_model(LinearGaussianModel(**values), 12)
    mapped = truth_from_model(MappedTruthModel(**values, map=np.eye(2)), 12)
    assert unmapped.error_map is None and mapped.error_map is not None
    filter_model = LinearGaussianModel(**{**values, "w": np.diag([0.01, 0.1])})
    a = FixedGainProblem(plain.info, filter_model, unmapped).block_sums(np.random.default_rng(9), 200, "exact")
    b = FixedGainProblem(plain.info, filter_model, mapped).block_sums(np.random.default_rng(9), 200, "exact")
    assert sums_equal(a, b)


def test_a_problem_refuses_a_map_that_does_not_fit_the_filter():
    scenario = _scenario(gm_std=1.0)
    plain = build_problem(scenario)[0]
    values = {key: getattr(scenario.truth, key) for key in MODEL_KEYS}
    truth = truth_from_model(MappedTruthModel(**values, map=np.eye(2)), 12)
    with pytest.raises(ValueError, match=r"truth: expected 1 filter states and 1 measurements, got 2 and 1"):
        FixedGainProblem(plain.info, scenario.filter, truth)


@pytest.mark.parametrize("x0_truth", [0.0, 2.0], ids=["centred", "offset-prior"])
def test_the_ensemble_agrees_with_the_joint_gaussian_of_all_errors(tmp_path, x0_truth):
    scenario = _scenario(gm_std=1.0, x0_truth=x0_truth)
    problem, cause = build_problem(scenario)
    if x0_truth:  # the means move only from a nonzero prior mean: a zero one is no model error
        assert cause == "the truth's own 2-state model (its x0, phi and h, mapped to the filter's 1 state)"
    else:
        assert cause == "" and not np.any(problem.expected_mean_error())
    mean, cov = _exact_errors(scenario)
    assert_close(problem.expected_mean_error(), mean, atol=1e-12, what="expected mean error")
    outcome = verify(scenario, N, 31, tmp_path, long_run=0)
    s = outcome.statistics
    k, d = mean.shape
    _, posterior = _gains(scenario.filter, k)
    assert_close(s.filter_cov, posterior, rtol=1e-12, atol=1e-15, what="filter P_k")
    sd = np.sqrt(np.diagonal(cov, axis1=1, axis2=2) / N)
    assert_close(s.mean_error, mean, atol=bonferroni_k(k * d) * sd, what="mean error")
    diag = np.diagonal(cov, axis1=1, axis2=2)
    cov_sd = np.sqrt((cov**2 + diag[:, :, None] * diag[:, None, :]) / N)
    assert_close(s.error_cov, cov, atol=bonferroni_k(k * d * d) * cov_sd, what="error covariance")
    # d = 1: N Cov_hat / sigma^2 ~ chi-square(N - 1) at each update; hold the last one to its 1e-4 quantiles
    ratio = (N - 1) * s.error_cov[-1, 0, 0] / cov[-1, 0, 0]
    lo, hi = scipy.stats.chi2.ppf([0.5e-4, 1 - 0.5e-4], N - 1)
    assert lo <= ratio <= hi, (ratio, lo, hi)
    # the filter ignores g: its P is well below the actual error variance
    assert np.all(diag[-4:, 0] > 1.5 * posterior[-4:, 0, 0])


def test_verify_fails_the_covariance_check_of_a_mistuned_reduced_order_filter(tmp_path):
    outcome = verify(_scenario(gm_std=1.0), N, 32, tmp_path / "coloured", long_run=0)
    verdicts = {t["name"]: t["passed"] for t in outcome.summary["tests"]}
    assert not verdicts["covariance"] and verdicts["mean_error"]
    np.testing.assert_array_equal(outcome.summary["settings"]["truth"]["map"], [[1.0, 0.0]])
    # a negligible coloured error (1 cm against 1 m of white noise): the reduced-order filter is consistent
    small = verify(_scenario(gm_std=0.01), N, 32, tmp_path / "small", long_run=0)
    assert {t["name"]: t["passed"] for t in small.summary["tests"]}["covariance"]
