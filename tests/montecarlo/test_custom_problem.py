"""A model file through the bench, against independent oracles.

* a plain numpy Riccati loop over every model step (no interval transition, no package code), and the
  steady state of the discrete algebraic Riccati equation that it approaches;
* the dense joint Gaussian of everything a run draws: every state at every model step and every fix is
  linear in u = [x_0 - x0, w_0 .. w_{Km-1}, v_1 .. v_K] ~ N(0, D), so the conditional covariance
  Cov(x_k | z_1..z_k), the exact mean error, error covariance and innovation correlations of a (possibly
  mistuned) filter are closed-form matrices; the Monte Carlo must agree with them within k sigma / sqrt(N).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.linalg

from kalcal.api.verification import verify
from kalcal.scenarios.model_file.model import load_model_file
from kalcal.montecarlo.scenarios import build_problem
from tests._helpers import assert_close, bonferroni_k

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
N = 20_000


def _riccati(model, n_updates: int):
    """Posterior covariances and gains by the textbook loop, one model step at a time (Joseph update)."""
    d = model.phi.shape[0]
    cov = np.array(model.m0)
    posteriors, gains = [], []
    for _ in range(n_updates):
        for _ in range(model.steps_per_update):
            cov = model.phi @ cov @ model.phi.T + model.gamma @ model.w @ model.gamma.T
        s = model.h @ cov @ model.h.T + model.v
        gain = np.linalg.solve(s, model.h @ cov).T  # P H^T S^-1 (S and P symmetric)
        joseph = np.eye(d) - gain @ model.h
        cov = joseph @ cov @ joseph.T + gain @ model.v @ gain.T
        posteriors.append(cov)
        gains.append(gain)
    return np.array(posteriors), np.array(gains)


class Dense:
    """The truth's states and fixes at the updates as maps of u ~ N(0, D), and a filter's estimates as maps of Z."""

    def __init__(self, truth, n_updates: int):
        d, q = truth.gamma.shape
        p = truth.h.shape[0]
        m = truth.steps_per_update
        steps = n_updates * m
        size = d + steps * q + n_updates * p
        self.d, self.p, self.k = d, p, n_updates
        self.cov_u = scipy.linalg.block_diag(truth.m0, *[truth.w] * steps, *[truth.v] * n_updates)
        state = np.zeros((d, size))
        state[:, :d] = np.eye(d)
        mean = np.array(truth.x0)
        x_maps, z_maps, x_means = [], [], []
        for j in range(steps):
            noise = np.zeros((d, size))
            noise[:, d + j * q : d + (j + 1) * q] = truth.gamma
            state = truth.phi @ state + noise
            mean = truth.phi @ mean
            if (j + 1) % m == 0:
                k = (j + 1) // m - 1
                fix = truth.h @ state
                fix[:, d + steps * q + k * p : d + steps * q + (k + 1) * p] += np.eye(p)
                x_maps.append(state)
                z_maps.append(fix)
                x_means.append(mean)
        self.x = np.array(x_maps)  # (K, d, size)
        self.z = np.concatenate(z_maps)  # (K p, size)
        self.x_mean = np.array(x_means)  # (K, d)
        self.z_mean = (np.array(x_means) @ truth.h.T).reshape(-1)

    def conditional_cov(self) -> np.ndarray:
        """Cov(x_k | z_1..z_k) of the joint Gaussian, (K, d, d): the optimal filter's P_k."""
        out = np.empty((self.k, self.d, self.d))
        for k in range(self.k):
            zk = self.z[: (k + 1) * self.p]
            sxx = self.x[k] @ self.cov_u @ self.x[k].T
            sxz = self.x[k] @ self.cov_u @ zk.T
            szz = zk @ self.cov_u @ zk.T
            out[k] = sxx - sxz @ np.linalg.solve(szz, sxz.T)
        return out

    def filter_maps(self, model, gains):
        """xhat_k = c_k + G_k Z and r_k = z_k - H xbar_k = a_k + R_k Z for the filter ``model`` with ``gains``."""
        phi_m = np.linalg.matrix_power(model.phi, model.steps_per_update)
        c, g = np.array(model.x0), np.zeros((self.d, self.k * self.p))
        estimates, residuals = [], []
        for k in range(self.k):
            c, g = phi_m @ c, phi_m @ g  # xbar_k
            r_const, r_map = -model.h @ c, -model.h @ g
            r_map[:, k * self.p : (k + 1) * self.p] += np.eye(self.p)
            residuals.append((r_const, r_map))
            c, g = c + gains[k] @ r_const, g + gains[k] @ r_map
            estimates.append((c, g))
        return estimates, residuals

    def error_moments(self, model, gains):
        """Exact E[e_k] (K, d), Cov(e_k) (K, d, d) and E[r_k r_j^T] (K, p, K, p) of the filter."""
        estimates, residuals = self.filter_maps(model, gains)
        mean = np.array([self.x_mean[k] - c - g @ self.z_mean for k, (c, g) in enumerate(estimates)])
        maps = np.array([self.x[k] - g @ self.z for k, (_, g) in enumerate(estimates)])
        cov = maps @ self.cov_u @ np.swapaxes(maps, 1, 2)
        r = np.concatenate([r_map @ self.z for _, r_map in residuals])  # (K p, size)
        r_moment = (r @ self.cov_u @ r.T).reshape(self.k, self.p, self.k, self.p)
        r_mean = np.array([a + r_map @ self.z_mean for a, r_map in residuals])
        return mean, cov, r_moment, r_mean


@pytest.fixture(scope="module")
def example():
    return load_model_file(EXAMPLES / "constant_velocity.toml")


@pytest.fixture(scope="module")
def mistuned():
    return load_model_file(EXAMPLES / "constant_velocity_mistuned.toml")


def test_covariance_pass_matches_a_plain_riccati_loop_and_approaches_the_dare(example):
    problem, cause = build_problem(example)
    f = example.filter
    posterior, gains = _riccati(f, example.model.updates)
    assert cause == ""
    assert_close(problem.schedule.posterior_cov, posterior, rtol=1e-12, atol=1e-15, what="P_k")
    assert_close(problem.schedule.gain, gains, rtol=1e-12, atol=1e-15, what="K_k")
    # the steady state: prior M from the DARE over one update interval, then one update
    phi_m = np.linalg.matrix_power(f.phi, f.steps_per_update)
    powers = [np.linalg.matrix_power(f.phi, i) for i in range(f.steps_per_update)]
    q_m = sum(a @ f.gamma @ f.w @ f.gamma.T @ a.T for a in powers)
    prior = scipy.linalg.solve_discrete_are(phi_m.T, f.h.T, q_m, f.v)
    steady = prior - prior @ f.h.T @ np.linalg.solve(f.h @ prior @ f.h.T + f.v, f.h @ prior)
    distance = np.abs(posterior - steady).max(axis=(1, 2)) / np.abs(steady).max()
    assert np.all(np.diff(distance) <= 0), distance
    assert distance[-1] < 1e-3 and distance[0] > 1.0


def test_the_filter_is_the_joint_gaussians_conditional(example):
    dense = Dense(example.truth, example.model.updates)
    posterior, gains = _riccati(example.filter, example.model.updates)
    conditional = dense.conditional_cov()
    assert_close(posterior, conditional, rtol=1e-9, atol=1e-12, what="P_k against Cov(x_k | z_1..z_k)")
    mean, cov, r_moment, r_mean = dense.error_moments(example.filter, gains)
    assert np.abs(mean).max() < 1e-12 and np.abs(r_mean).max() < 1e-12
    assert_close(cov, posterior, rtol=1e-9, atol=1e-12, what="exact error covariance against P_k")
    k, p = example.model.updates, 1
    off = ~np.eye(k * p, dtype=bool).reshape(k, p, k, p)
    assert np.abs(r_moment[off]).max() < 1e-9  # white innovations


def _check_ensemble(scenario, tmp_path, seed):
    """Run the bench and hold its statistics to the dense joint Gaussian's exact moments."""
    outcome = verify(scenario, N, seed, tmp_path, long_run=0)
    s = outcome.statistics
    posterior, gains = _riccati(scenario.filter, scenario.model.updates)
    mean, cov, r_moment, _ = Dense(scenario.truth, scenario.model.updates).error_moments(scenario.filter, gains)
    k, d = mean.shape
    assert_close(s.filter_cov, posterior, rtol=1e-12, atol=1e-15, what="filter P_k")
    sd = np.sqrt(np.diagonal(cov, axis1=1, axis2=2) / N)
    assert_close(s.mean_error, mean, atol=bonferroni_k(k * d) * sd, what="mean error")
    diag = np.diagonal(cov, axis1=1, axis2=2)
    cov_sd = np.sqrt((cov**2 + diag[:, :, None] * diag[:, None, :]) / N)
    assert_close(s.error_cov, cov, atol=bonferroni_k(k * d * d) * cov_sd, what="error covariance")
    power = np.diagonal(r_moment.reshape(k, k), axis1=0, axis2=1)  # p = 1
    r_sd = np.sqrt((r_moment[:, 0, :, 0] ** 2 + np.outer(power, power)) / N)
    r_atol = bonferroni_k(k * k) * r_sd
    assert_close(s.residual_second_moment[:, 0, :, 0], r_moment[:, 0, :, 0], atol=r_atol, what="E[r_k r_j]")
    return outcome, posterior, cov


def test_the_ensemble_agrees_with_the_joint_gaussian(example, tmp_path):
    outcome, posterior, cov = _check_ensemble(example, tmp_path, seed=11)
    assert outcome.summary["verdict"] == "pass"


def test_a_mistuned_filters_ensemble_agrees_with_the_joint_gaussian_not_with_p(mistuned, tmp_path):
    outcome, posterior, cov = _check_ensemble(mistuned, tmp_path, seed=12)
    # the actual error variance is over twice the filter's P: the covariance check must fail
    ratio = np.diagonal(cov, axis1=1, axis2=2) / np.diagonal(posterior, axis1=1, axis2=2)
    assert ratio[-1].min() > 2.0
    verdicts = {t["name"]: t["passed"] for t in outcome.summary["tests"]}
    assert not verdicts["covariance"] and verdicts["mean_error"]
