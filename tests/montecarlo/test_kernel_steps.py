"""The compiled block kernels, update by update, against the numpy reference steps.

A block of one realization makes the kernels' sums that realization's own numbers (its estimate, error,
innovation and, for the regression kernel, P_k and NIS), and the kept innovations give every
realization's r_k: so each update of the compiled recursion is compared with
:func:`kalcal.core.steps.predict` and :func:`~kalcal.core.steps.update` (fixed gains), and with
:func:`kalcal.filters.regression.run_regression_filter`, which runs those steps (data-dependent gains).
"""

from __future__ import annotations

import numpy as np
import pytest

from kalcal.core.steps import gain_and_covariance, nis, predict, predict_covariance, update
from kalcal.filters.regression import run_regression_filter
from kalcal.montecarlo.accumulators import SumBuffers
from kalcal.montecarlo.kernels import filter_block_moments
from kalcal.scenarios.scale_bias.kernels import regression_block_moments


def _spd(rng, d):
    a = rng.standard_normal((d, d))
    return a @ a.T + 0.5 * np.eye(d)


def test_fixed_gain_kernel_equals_predict_and_update_at_every_step():
    rng = np.random.default_rng(5)
    d, p, n_updates, n = 3, 2, 12, 4
    phis = np.eye(d) + 0.2 * rng.standard_normal((n_updates, d, d))
    h = rng.standard_normal((p, d))
    q, v, m0 = _spd(rng, d), _spd(rng, p), _spd(rng, d)
    x0 = rng.standard_normal(d)
    priors, posteriors, gains, cov = [], [], [], m0
    for k in range(n_updates):
        cov = predict_covariance(cov, phis[k], q)
        priors.append(cov)
        gain, cov, _ = gain_and_covariance(cov, h, v)
        gains.append(gain)
        posteriors.append(cov)
    gains = np.array(gains)
    truth = rng.standard_normal((n_updates, d, n))
    z = rng.standard_normal((n_updates, p, n))
    # the shape histograms' whiteners of P_k and S_k: any W serves this test, which reads no histogram
    whiteners = (np.tile(np.eye(d), (n_updates, 1, 1)), np.tile(np.eye(p), (n_updates, 1, 1)),
                 np.zeros((n_updates, d)), np.zeros((n_updates, p)))
    for i in range(n):
        sums = SumBuffers.zeros(n_updates, d, p, 1, True)
        filter_block_moments(truth[:, :, i:i + 1].copy(), z[:, :, i:i + 1].copy(), phis, h, gains, x0, *whiteners, sums)
        x = x0
        for k in range(n_updates):
            xbar, _ = predict(x, priors[k], phis[k], q)
            step = update(xbar, priors[k], z[k, :, i], h, v)
            # the optimal gain by another identity, K = P H^T V^{-1} from the posterior P: the kernel's
            # schedule is the Kalman gain, not merely the same function's output twice
            np.testing.assert_allclose(gains[k], np.linalg.solve(v, h @ posteriors[k]).T, rtol=1e-10, atol=1e-12)
            x = step.x
            scale = np.abs(x).max()
            np.testing.assert_allclose(sums.estimate[k], x, rtol=1e-12, atol=1e-13 * scale)
            np.testing.assert_allclose(sums.error[k], truth[k, :, i] - x, rtol=1e-12, atol=1e-13 * scale)
            np.testing.assert_allclose(sums.residuals[k * p:(k + 1) * p, 0], step.residual, rtol=1e-12, atol=1e-13)
    # all realizations in one block: each one's innovations, and the sum of their estimates
    sums = SumBuffers.zeros(n_updates, d, p, n, True)
    filter_block_moments(truth.copy(), z.copy(), phis, h, gains, x0, *whiteners, sums)
    x = np.broadcast_to(x0, (n, d))
    for k in range(n_updates):
        xbar, _ = predict(x, priors[k], phis[k], q)
        step = update(xbar, priors[k], z[k].T, h, v)
        x = step.x
        np.testing.assert_allclose(sums.residuals[k * p:(k + 1) * p].T, step.residual, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(sums.estimate[k], x.sum(axis=0), rtol=1e-12, atol=1e-12 * np.abs(x).max())


@pytest.mark.parametrize("form", ["joseph", "standard"])
def test_regression_kernel_equals_the_regression_filter_at_every_step(form):
    rng = np.random.default_rng(8)
    d, n_updates, n = 2, 40, 3
    zeta = 1.0 + rng.standard_normal((n, n_updates))
    h = np.stack([zeta, np.ones_like(zeta)], axis=-1)  # h_k = [z_k, 1]
    truth = np.array([1.02, -0.3]) + 0.01 * rng.standard_normal((n, n_updates, d))
    y = np.einsum("nkd,nkd->nk", h, truth) + 0.1 * rng.standard_normal((n, n_updates))
    x0, cov0, r = np.array([1.0, 0.0]), np.diag([0.04, 0.25]), 0.01
    q = np.diag([1e-6, 4e-6])
    for i in range(n):
        sums = SumBuffers.zeros(n_updates, d, 1, 1, True, own_cov=True)
        regression_block_moments(y[i:i + 1].copy(), h[i:i + 1].copy(), truth[i:i + 1].copy(), x0, cov0, r, q, form == "joseph", sums)
        run = run_regression_filter(y[i], h[i], x0, cov0, r, q, form)
        error = truth[i] - run.posterior
        np.testing.assert_allclose(sums.estimate, run.posterior, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(sums.error, error, rtol=1e-10, atol=1e-14)
        np.testing.assert_allclose(sums.filter_cov, run.cov, rtol=1e-12, atol=1e-16)
        # the pairs are kept of the innovations normalized by each realization's own S_k
        normalized = run.residual / np.sqrt(run.innovation_var)
        np.testing.assert_allclose(sums.residuals[:, 0], normalized, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(sums.nis, nis(run.residual[:, None], run.innovation_var[:, None, None]), rtol=1e-10)
        nees = np.einsum("ki,ki->k", error, np.linalg.solve(run.cov, error[..., None])[..., 0])
        np.testing.assert_allclose(sums.nees, nees, rtol=1e-9)
        # eps = L^-1 e by the filter's own P_k, L lower Cholesky: |eps|^2 is the NEES
        white = np.linalg.solve(np.linalg.cholesky(run.cov), error[..., None])[..., 0]
        np.testing.assert_allclose(sums.whitened_error, white, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(sums.whitened_outer, white[:, :, None] * white[:, None, :], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(sums.whitened_estimate, white[:, :, None] * run.posterior[:, None, :], rtol=1e-9, atol=1e-12)
