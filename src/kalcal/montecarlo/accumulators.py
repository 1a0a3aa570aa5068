"""Mergeable streaming sums of a Monte Carlo ensemble, and the statistics derived from them.

Each block of realizations becomes a :class:`MomentSums`; sums merge by addition, so memory is flat in
the number of realizations and any grouping of blocks, merged in block order, gives the same bits.
:meth:`MomentSums.from_block` is the numpy definition of a block's sums; the compiled kernels add into
the same fields, allocated once by :meth:`SumBuffers.zeros` (:mod:`kalcal.montecarlo.sum_kernels`).
Second moments are raw sums; central moments are derived at the end in float64 (the errors' means are
small against their spread, so the subtraction loses no meaningful precision).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import NamedTuple

import numpy as np


class BlockResult(NamedTuple):
    """n realizations of a filter run, K updates, d states, p measurements."""

    error: np.ndarray  #: e_k = x_k - xhat_k, (n, K, d)
    estimate: np.ndarray  #: xhat_k, (n, K, d)
    residual: np.ndarray  #: r_k = z_k - H xbar_k, (n, K, p)
    nees: np.ndarray  #: e_k^T P_k^{-1} e_k, (n, K)
    nis: np.ndarray  #: r_k^T S_k^{-1} r_k, (n, K)
    filter_cov_sum: np.ndarray  #: sum over the n realizations of the filter's P_k, (K, d, d)
    #: each realization's own P_k, (n, K, d, d): a broadcast view of one schedule for fixed gains, its own
    #: for data-dependent gains; required, so that a realization's P is never a block mean
    filter_cov: np.ndarray
    normalized_residual: np.ndarray | None = None  #: L_k^{-1} r_k with S_k = L_k L_k^T, (n, K, p), if known


class ResidualProducts:
    """The sum of r r^T over the stacked residual vector, kept as its upper triangle."""

    @staticmethod
    def upper(stacked: np.ndarray) -> np.ndarray:
        """Upper triangle of sum_i r_i r_i^T for the innovations of n realizations, by numpy's BLAS syrk.

        numpy forms A A^T of one array with its own transpose by syrk and releases the GIL while BLAS runs,
        so the engine's threads overlap here. Its last bits are those of the BLAS numpy carries on this CPU
        (scipy's dsyrk, another build, may round an element an ulp apart); each element is within
        gamma_n sum_i |r_ai r_bi| of the exact sum, gamma_n = n u / (1 - n u), u = 2^-53.

        Parameters
        ----------
        stacked : ndarray, shape (K p, n), C-ordered
            One column per realization, its K stacked innovations (update-major).
        """
        width, n = stacked.shape
        if n == 0:
            return np.zeros((width, width))
        return np.triu(stacked @ stacked.T)


class SumBuffers(NamedTuple):
    """The arrays a compiled kernel adds one block into: the fields of :class:`MomentSums` it fills.

    A kernel sees them as one argument with named fields (numba types a NamedTuple); K updates, d
    states, p measurements, n realizations.
    """

    error: np.ndarray  #: sum e_k, (K, d)
    error_outer: np.ndarray  #: sum e_k e_k^T, (K, d, d)
    estimate: np.ndarray  #: sum xhat_k, (K, d)
    estimate_outer: np.ndarray  #: sum xhat_k xhat_k^T, (K, d, d)
    error_estimate: np.ndarray  #: sum e_k xhat_k^T, (K, d, d)
    nees: np.ndarray  #: sum e^T P^{-1} e, (K,)
    nis: np.ndarray  #: sum r^T S^{-1} r, (K,)
    residual: np.ndarray  #: sum r_k, (K, p)
    residual_own: np.ndarray  #: sum r_k r_k^T, (K, p, p)
    filter_cov: np.ndarray  #: sum of the filter's P_k, (K, d, d)
    #: each realization's stacked innovations [r_0; ...; r_{K-1}] as a column, (K p, n), for the pair
    #: sums after the kernel; (0, n) when the pairs are not kept
    residuals: np.ndarray

    @classmethod
    def zeros(cls, n_updates: int, d: int, p: int, n: int, residual_pairs: bool) -> SumBuffers:
        """Zero sums for K = ``n_updates``, and room for the innovations of n realizations if the pairs are kept."""
        return cls(
            error=np.zeros((n_updates, d)),
            error_outer=np.zeros((n_updates, d, d)),
            estimate=np.zeros((n_updates, d)),
            estimate_outer=np.zeros((n_updates, d, d)),
            error_estimate=np.zeros((n_updates, d, d)),
            nees=np.zeros(n_updates),
            nis=np.zeros(n_updates),
            residual=np.zeros((n_updates, p)),
            residual_own=np.zeros((n_updates, p, p)),
            filter_cov=np.zeros((n_updates, d, d)),
            residuals=np.empty((n_updates * p if residual_pairs else 0, n)),
        )


@dataclass
class MomentSums:
    """Sums over realizations. K updates, d states, p measurements.

    ``residual_outer`` holds the upper triangle of sum r r^T over the stacked residual vector
    [r_0, r_1, ..., r_{K-1}] (length K p, update-major); its lower triangle is zero until
    :func:`residual_second_moment` fills it. It is None when the run did not keep the pairs (it costs
    O(N K^2 p^2)); ``residual_own`` (the same update's products, for NIS) is always kept.
    """

    count: int
    error: np.ndarray  #: sum e_k, (K, d)
    error_outer: np.ndarray  #: sum e_k e_k^T, (K, d, d)
    estimate: np.ndarray  #: sum xhat_k, (K, d)
    estimate_outer: np.ndarray  #: sum xhat_k xhat_k^T, (K, d, d)
    error_estimate: np.ndarray  #: sum e_k xhat_k^T, (K, d, d)
    nees: np.ndarray  #: sum e^T P^{-1} e, (K,)
    nis: np.ndarray  #: sum r^T S^{-1} r, (K,)
    residual: np.ndarray  #: sum r_k, (K, p)
    residual_own: np.ndarray  #: sum r_k r_k^T, (K, p, p)
    residual_outer: np.ndarray | None  #: upper triangle of sum r r^T over all pairs, (K p, K p)
    filter_cov: np.ndarray  #: sum of the filter's P_k, (K, d, d)
    normalized_residual: np.ndarray | None = None  #: sum of L_k^{-1} r_k, (K, p), where the problem knows S_k

    @classmethod
    def from_block(cls, block: BlockResult) -> MomentSums:
        """The sums of one block (n realizations)."""
        e = np.ascontiguousarray(block.error.transpose(1, 0, 2))  # (K, n, d)
        x = np.ascontiguousarray(block.estimate.transpose(1, 0, 2))
        n, n_updates, p = block.residual.shape
        outer = ResidualProducts.upper(np.ascontiguousarray(block.residual.reshape(n, n_updates * p).T))
        return cls(
            count=n,
            error=e.sum(axis=1),
            error_outer=np.swapaxes(e, 1, 2) @ e,
            estimate=x.sum(axis=1),
            estimate_outer=np.swapaxes(x, 1, 2) @ x,
            error_estimate=np.swapaxes(e, 1, 2) @ x,
            nees=block.nees.sum(axis=0),
            nis=block.nis.sum(axis=0),
            residual=block.residual.sum(axis=0),
            residual_own=np.einsum("nka,nkb->kab", block.residual, block.residual),
            residual_outer=outer,
            filter_cov=np.asarray(block.filter_cov_sum, dtype=float),
            normalized_residual=None if block.normalized_residual is None else block.normalized_residual.sum(axis=0),
        )

    @classmethod
    def from_buffers(cls, count: int, buffers: SumBuffers, normalized_residual: np.ndarray | None = None) -> MomentSums:
        """The sums of ``count`` realizations that a kernel added into ``buffers`` (the pairs by syrk)."""
        sums = buffers._asdict()
        residuals = sums.pop("residuals")
        outer = ResidualProducts.upper(residuals) if residuals.shape[0] else None
        return cls(count=count, **sums, residual_outer=outer, normalized_residual=normalized_residual)

    def merge(self, other: MomentSums) -> MomentSums:
        """The sums of both ensembles (self first, then other: the order fixes the rounding)."""
        def add(a, b):
            return None if a is None or b is None else a + b

        return MomentSums(
            count=self.count + other.count,
            **{f.name: add(getattr(self, f.name), getattr(other, f.name)) for f in fields(self) if f.name != "count"},
        )


def residual_second_moment(sums: MomentSums) -> np.ndarray | None:
    """E[r_k r_j^T] for every pair, as the full symmetric (K, p, K, p) array (None if not kept)."""
    upper = sums.residual_outer
    if upper is None:
        return None
    full = upper + np.triu(upper, 1).T
    n_updates, p = sums.residual.shape
    return (full / sums.count).reshape(n_updates, p, n_updates, p)


@dataclass(frozen=True)
class EnsembleStatistics:
    """Per-update statistics of the ensemble. N realizations, K updates."""

    count: int
    mean_error: np.ndarray  #: (K, d)
    error_cov: np.ndarray  #: ensemble covariance of e, divisor N - 1, (K, d, d)
    error_second_moment: np.ndarray  #: E[e e^T], (K, d, d)
    estimate_second_moment: np.ndarray  #: E[xhat xhat^T], (K, d, d)
    error_estimate: np.ndarray  #: E[e xhat^T], (K, d, d)
    mean_estimate: np.ndarray  #: (K, d)
    filter_cov: np.ndarray  #: mean of the filter's P_k, (K, d, d)
    mean_nees: np.ndarray  #: (K,)
    mean_nis: np.ndarray  #: (K,)
    mean_residual: np.ndarray  #: (K, p)
    residual_own_moment: np.ndarray  #: E[r_k r_k^T], (K, p, p)
    residual_second_moment: np.ndarray | None  #: E[r_k r_j^T] over all pairs, (K, p, K, p), if kept
    mean_normalized_residual: np.ndarray | None = None  #: E[L_k^{-1} r_k], (K, p), where known


def ensemble_statistics(sums: MomentSums) -> EnsembleStatistics:
    """Means and (co)variances from the sums."""
    n = sums.count
    if n < 2:
        raise ValueError(f"need at least two realizations for ensemble statistics, got {n}")
    mean_error = sums.error / n
    centered = sums.error_outer - n * mean_error[:, :, None] * mean_error[:, None, :]
    return EnsembleStatistics(
        count=n,
        mean_error=mean_error,
        error_cov=centered / (n - 1),
        error_second_moment=sums.error_outer / n,
        estimate_second_moment=sums.estimate_outer / n,
        error_estimate=sums.error_estimate / n,
        mean_estimate=sums.estimate / n,
        filter_cov=sums.filter_cov / n,
        mean_nees=sums.nees / n,
        mean_nis=sums.nis / n,
        mean_residual=sums.residual / n,
        residual_own_moment=sums.residual_own / n,
        residual_second_moment=residual_second_moment(sums),
        mean_normalized_residual=None if sums.normalized_residual is None else sums.normalized_residual / n,
    )
