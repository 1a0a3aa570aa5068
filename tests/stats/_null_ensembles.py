"""Ensemble statistics of a correct filter drawn directly from their exact laws, without a Monte Carlo.

For a correct fixed-gain filter the N realizations' (e_k, xhat_k) are iid normal with e_k ~ N(0, P_k)
independent of xhat_k, and the innovations are N(0, S_k), independent across updates. The checks read
only the ensemble moments, and these have exact laws: the centered scatter of the stacked (e, xhat)
is Wishart(Sigma, N - 1) and independent of its mean, N(mu, Sigma / N); the pair sums of the
innovations are the Gram matrix of an N x K p normal sample; N times the mean NIS is chi-square(N p).
Each draw is one ensemble of N realizations, so that tens of thousands of ensembles cost seconds.

Where P_k differs between realizations (:func:`own_cov_statistics`) the moments have no such closed
law: those ensembles are drawn realization by realization and summed by the accumulators' own code.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from kalcal.montecarlo.accumulators import BlockResult, EnsembleStatistics, MomentSums, ensemble_statistics
from kalcal.montecarlo.problem import ProblemInfo


def info(n_updates: int, d: int, p: int) -> ProblemInfo:
    return ProblemInfo(
        "synthetic",
        np.arange(1, n_updates + 1, dtype=float),
        tuple(f"x{i}" for i in range(d)),
        ("m",) * d,
        tuple(f"z{a}" for a in range(p)),
        ("m",) * p,
    )


def filter_covariances(rng: np.random.Generator, n_updates: int, d: int) -> np.ndarray:
    """P_k (K, d, d), correlated and of unequal scales, as a filter's are."""
    a = rng.standard_normal((n_updates, d, d))
    scale = np.exp(rng.uniform(-3.0, 3.0, (n_updates, d)))
    return scale[:, :, None] * (a @ np.swapaxes(a, 1, 2) + 0.5 * np.eye(d)) * scale[:, None, :]


def wishart(rng: np.random.Generator, factor: np.ndarray, dof: int, size: int) -> np.ndarray:
    """``size`` draws of Wishart(L L^T, dof) for each factor L (K, D, D), by Bartlett's decomposition:
    (size, K, D, D)."""
    n_updates, dim, _ = factor.shape
    b = np.tril(rng.standard_normal((size, n_updates, dim, dim)), -1)
    diag = np.sqrt(rng.chisquare(dof - np.arange(dim), (size, n_updates, dim)))
    b[..., np.arange(dim), np.arange(dim)] = diag
    lb = factor @ b
    return lb @ np.swapaxes(lb, -1, -2)


def state_statistics(rng: np.random.Generator, p_cov: np.ndarray, n: int, size: int) -> list[EnsembleStatistics]:
    """``size`` ensembles of N = ``n`` realizations of a correct filter with P_k = ``p_cov`` (K, d, d):
    their state moments (error, estimate) exactly, the innovation moments left neutral."""
    n_updates, d, _ = p_cov.shape
    # the estimate: any law independent of the error; here normal with a mean and correlations of its own
    x_cov = filter_covariances(rng, n_updates, d) * 4.0
    x_mean = rng.standard_normal((n_updates, d)) * np.sqrt(np.diagonal(x_cov, axis1=1, axis2=2)) * 2.0
    sigma = np.zeros((n_updates, 2 * d, 2 * d))
    sigma[:, :d, :d], sigma[:, d:, d:] = p_cov, x_cov
    factor = np.linalg.cholesky(sigma)
    scatter = wishart(rng, factor, n - 1, size)  # (size, K, 2d, 2d): centered sum of products
    mean = np.concatenate([np.zeros((n_updates, d)), x_mean], axis=1)
    mean = mean + np.einsum("kab,skb->ska", factor, rng.standard_normal((size, n_updates, 2 * d))) / np.sqrt(n)
    raw = scatter + n * mean[..., :, None] * mean[..., None, :]
    out = []
    for i in range(size):
        e, x = mean[i, :, :d], mean[i, :, d:]
        out.append(
            EnsembleStatistics(
                count=n,
                mean_error=e,
                error_cov=scatter[i, :, :d, :d] / (n - 1),
                error_second_moment=raw[i, :, :d, :d] / n,
                estimate_second_moment=raw[i, :, d:, d:] / n,
                error_estimate=raw[i, :, :d, d:] / n,
                mean_estimate=x,
                filter_cov=p_cov,
                mean_nees=np.full(n_updates, float(d)),
                mean_nis=np.ones(n_updates),
                mean_residual=np.zeros((n_updates, 1)),
                residual_own_moment=np.ones((n_updates, 1, 1)),
                residual_second_moment=None,
            )
        )
    return out


def innovation_statistics(rng: np.random.Generator, n_updates: int, p: int, n: int) -> EnsembleStatistics:
    """One ensemble's innovation moments: N realizations of K independent N(0, S_k) innovations (the
    pairs from the N x K p sample itself: below K p dimensions the Wishart is singular), and its mean NIS."""
    a = rng.standard_normal((n_updates, p, p))
    s_factor = np.linalg.cholesky(a @ np.swapaxes(a, 1, 2) + np.eye(p))
    r = np.einsum("kab,nkb->nka", s_factor, rng.standard_normal((n, n_updates, p)))
    stacked = r.reshape(n, n_updates * p)
    moment = (stacked.T @ stacked / n).reshape(n_updates, p, n_updates, p)
    own = moment[np.arange(n_updates), :, np.arange(n_updates), :]
    d = 1
    return EnsembleStatistics(
        count=n,
        mean_error=np.zeros((n_updates, d)),
        error_cov=np.ones((n_updates, d, d)),
        error_second_moment=np.ones((n_updates, d, d)),
        estimate_second_moment=np.ones((n_updates, d, d)),
        error_estimate=np.zeros((n_updates, d, d)),
        mean_estimate=np.zeros((n_updates, d)),
        filter_cov=np.ones((n_updates, d, d)),
        mean_nees=np.ones(n_updates),
        mean_nis=rng.chisquare(n * p, n_updates) / n,
        mean_residual=r.mean(axis=0),
        residual_own_moment=own,
        residual_second_moment=moment,
    )


def own_cov_statistics(rng: np.random.Generator, p_cov: np.ndarray, n: int, spread: float = 1.5) -> EnsembleStatistics:
    """One ensemble of N = ``n`` realizations of a correct filter whose P_k differs between realizations
    (data-dependent gains, as scale-bias's), its sums built by :meth:`MomentSums.from_block`, the numpy
    definition the compiled kernels are held to (each realization whitened by its own P_k).

    Realization j has P_jk = D_jk ``p_cov``_k D_jk, D_jk diagonal with entries exp(U(-spread, spread))
    (unequal scales per realization, update and state), and error e_jk = L_jk z_jk, z_jk ~ N(0, I) (so
    eps_jk = L_jk^-1 e_jk ~ N(0, I) exactly). Its estimate depends on P_jk (a filter's estimate and P both
    follow the data) and not on z: the error stays independent of it given P, as for a correct filter.
    The error's ensemble covariance is then a scale mixture of normals with mean the mean P, not
    normal: whitened by the mean P its variances are not chi-square (the check's bound would be
    anticonservative; :func:`without_own_whitening`).
    """
    n_updates, d, _ = p_cov.shape
    scale = np.exp(rng.uniform(-spread, spread, (n, n_updates, d)))
    p_own = scale[..., :, None] * p_cov[None] * scale[..., None, :]  # (N, K, d, d)
    factor = np.linalg.cholesky(p_own)
    error = np.einsum("nkab,nkb->nka", factor, rng.standard_normal((n, n_updates, d)))
    sd = np.sqrt(np.diagonal(p_own, axis1=2, axis2=3))
    estimate = 3.0 * sd + sd * rng.standard_normal((n, n_updates, d)) + rng.standard_normal((n_updates, d))
    residual = rng.standard_normal((n, n_updates, 1))
    whitened = np.linalg.solve(factor, error[..., None])[..., 0]
    block = BlockResult(
        error=error,
        estimate=estimate,
        residual=residual,
        nees=np.sum(whitened**2, axis=2),
        nis=residual[..., 0] ** 2,
        filter_cov_sum=p_own.sum(axis=0),
        filter_cov=p_own,
    )
    return ensemble_statistics(MomentSums.from_block(block))


def without_own_whitening(s: EnsembleStatistics) -> EnsembleStatistics:
    """``s`` without its per-realization whitened moments: the checks then whiten by the mean P."""
    return dataclasses.replace(s, mean_whitened_error=None, whitened_second_moment=None, whitened_estimate=None)
