"""Mergeable streaming sums of a Monte Carlo ensemble, and the statistics derived from them.

Each block of realizations becomes a :class:`MomentSums`; sums merge by addition, so memory is flat in
the number of realizations and any grouping of blocks, merged in block order, gives the same bits.
:meth:`MomentSums.from_block` is the numpy definition of a block's sums; the compiled kernels add into
the same fields, allocated once by :meth:`SumBuffers.zeros` (:mod:`kalcal.montecarlo.sum_kernels`).
Second moments are raw sums; central moments are derived at the end in float64 (the errors' means are
small against their spread, so the subtraction loses no meaningful precision).

**Whitened errors.** The covariance and orthogonality checks test eps_k = L_k^-1 e_k (P_k = L_k L_k^T,
the filter's own P), which is exactly N(0, I) and independent of the estimate for a correct filter.
Where every realization shares P_k (fixed gains) the whitened sums follow from the raw ones
(sum eps = L^-1 sum e, sum eps eps^T = L^-1 (sum e e^T) L^-T), so the sums keep none
(``whitened_error`` is None) and :func:`ensemble_statistics` derives them. Where P_k depends on the data
(scale-bias) each realization is whitened by its own P_k and the sums keep sum eps, sum eps eps^T and
sum eps xhat^T: the mean P is no valid reference when P varies (by Jensen's inequality a whitening by it
is not N(0, I)).

**The shape of NEES and NIS.** Each realization's NEES at update k is chi-square(d) and its NIS
chi-square(p) under the null, so u = F_chi2(NEES) is U(0, 1). The sums keep, per update, a histogram of
each value on :data:`SHAPE_BINS` bins equal in sqrt(x) (``nees_histogram``, ``nis_histogram``, counts
(K, B)), summed per block like every other sum, so that :mod:`kalcal.stats.shape` tests the pooled values
against chi-square with memory flat in N (:class:`ShapeGrid`: no chi-square function is evaluated per
realization, nor any here).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import NamedTuple

import numpy as np

#: bins of each update's NEES and NIS histograms (B): equal in sqrt(x), over [0, sqrt(dof) + SHAPE_SPAN]
SHAPE_BINS = 2048
#: the histograms' span in sqrt(x) past sqrt(dof): chi(dof) = sqrt(chi-square(dof)) lies beyond sqrt(dof) + 6
#: with probability below 1e-9 for every dof (its spread is about 0.7); values beyond fall in the last bin
SHAPE_SPAN = 6.0


class ShapeGrid(NamedTuple):
    """The bins of a chi-square(dof) value x: bin j = min(floor(sqrt(x) ``scale``), B - 1) (0 for x <= 0),
    so that bin j holds (j / scale)^2 <= x < ((j + 1) / scale)^2, the last bin everything above.

    Equal bins of sqrt(x), not of u = F(x): binning needs no chi-square quantile (numpy and the compiled
    kernels compute the same floor of the same product, so they bin each value alike), and
    :mod:`kalcal.stats.shape` compares the counts below x_j = (j / scale)^2 with F(x_j). The steps of u
    between grid points are at most the density of chi(dof) (below sqrt(2 / pi) ~ 0.80) times
    1 / scale, about 0.003 at dof 3.
    """

    scale: float  #: bins per unit of sqrt(x): B / (sqrt(dof) + SHAPE_SPAN)


def shape_grid(dof: int, bins: int = SHAPE_BINS) -> ShapeGrid:
    """The :class:`ShapeGrid` of chi-square(``dof``) values on ``bins`` bins."""
    return ShapeGrid(float(bins / (np.sqrt(dof) + SHAPE_SPAN)))


def shape_points(dof: int, bins: int = SHAPE_BINS) -> np.ndarray:
    """x_j = (j / scale)^2, j = 1 .. B - 1: the grid points whose counts below are known exactly, (B - 1,)."""
    return (np.arange(1, bins) / shape_grid(dof, bins).scale) ** 2


def shape_histogram(values: np.ndarray, dof: int) -> np.ndarray:
    """Counts (K, B) of each update's values (n, K) on :func:`shape_grid`'s bins: the numpy definition of
    the histograms the compiled kernels add into (NaN counted in the last bin)."""
    scale = shape_grid(dof).scale
    n_updates = values.shape[1]
    with np.errstate(invalid="ignore"):
        where = np.sqrt(np.where(values > 0.0, values, 0.0)) * scale
        where = np.where(np.isnan(values), SHAPE_BINS - 1.0, np.minimum(where, SHAPE_BINS - 1.0))
    index = where.astype(np.int64) + SHAPE_BINS * np.arange(n_updates)
    return np.bincount(index.ravel(), minlength=n_updates * SHAPE_BINS).reshape(n_updates, SHAPE_BINS).astype(np.int64)


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
    #: the values the shape histograms bin, (n, K) each: the NEES and NIS of the error and innovation
    #: centered on their predicted means (a fixed-gain problem's model error); None: ``nees`` and ``nis``
    shape_nees: np.ndarray | None = None
    shape_nis: np.ndarray | None = None


def shares_cov(filter_cov: np.ndarray) -> bool:
    """Whether a block's per-realization P (n, K, d, d) is one schedule broadcast over the realizations
    (fixed gains: a view of stride 0 along n), so that the whitened sums follow from the raw ones."""
    return filter_cov.shape[0] <= 1 or filter_cov.strides[0] == 0


def whiten(filter_cov: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """eps = L^-1 v with P = L L^T (lower Cholesky factor), by a triangular solve.

    filter_cov (..., d, d) and vectors (..., d) broadcast together; returns (..., d).
    """
    factor = np.linalg.cholesky(filter_cov)
    return _solve_lower(factor, vectors)


def _solve_lower(factor: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """x with L x = v for lower-triangular L (..., d, d), by forward substitution (d is small)."""
    factor, vectors = np.broadcast_arrays(factor, vectors[..., None])
    vectors = vectors[..., 0]
    d = factor.shape[-1]
    out = np.empty(vectors.shape)
    for a in range(d):
        out[..., a] = (vectors[..., a] - np.einsum("...b,...b->...", factor[..., a, :a], out[..., :a])) / factor[..., a, a]
    return out


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
    #: sums after the kernel; (0, n) when the pairs are not kept. A kernel whose S_k varies between
    #: realizations stores the normalized innovations L_k^-1 r_k here (see :class:`MomentSums`)
    residuals: np.ndarray
    #: sum eps_k, eps_k = L_k^-1 e_k with each realization's own P_k, (K, d); (0, d) where P_k is shared
    whitened_error: np.ndarray
    whitened_outer: np.ndarray  #: sum eps_k eps_k^T, (K, d, d); (0, d, d) where P_k is shared
    whitened_estimate: np.ndarray  #: sum eps_k xhat_k^T, (K, d, d); (0, d, d) where P_k is shared
    nees_histogram: np.ndarray  #: counts of the NEES per update on :func:`shape_grid`'s bins, int64 (K, B)
    nis_histogram: np.ndarray  #: counts of the NIS likewise, int64 (K, B)
    nees_grid: ShapeGrid  #: the bins of the NEES (chi-square(d)); read only, not a sum
    nis_grid: ShapeGrid  #: the bins of the NIS (chi-square(p)); read only, not a sum

    @classmethod
    def zeros(
        cls, n_updates: int, d: int, p: int, n: int, residual_pairs: bool, own_cov: bool = False
    ) -> SumBuffers:
        """Zero sums for K = ``n_updates``, and room for the innovations of n realizations if the pairs are
        kept; ``own_cov``: every realization has its own P_k, so the whitened sums are kept."""
        kept = n_updates if own_cov else 0
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
            whitened_error=np.zeros((kept, d)),
            whitened_outer=np.zeros((kept, d, d)),
            whitened_estimate=np.zeros((kept, d, d)),
            nees_histogram=np.zeros((n_updates, SHAPE_BINS), dtype=np.int64),
            nis_histogram=np.zeros((n_updates, SHAPE_BINS), dtype=np.int64),
            nees_grid=shape_grid(d),
            nis_grid=shape_grid(p),
        )


@dataclass
class MomentSums:
    """Sums over realizations. K updates, d states, p measurements.

    ``residual_outer`` holds the upper triangle of sum r r^T over the stacked residual vector
    [r_0, r_1, ..., r_{K-1}] (length K p, update-major); its lower triangle is zero until
    :func:`residual_second_moment` fills it. It is None when the run did not keep the pairs (it costs
    O(N K^2 p^2)); ``residual_own`` (the same update's products, for NIS) is always kept. Where S_k varies
    between realizations (``whitened_error`` kept) the pairs are those of the normalized innovations
    L_k^-1 r_k, which are N(0, I) and independent across updates for a correct filter (the raw ones, of
    varying variance, are not identically distributed over the realizations).
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
    #: sum of eps_k = L_k^-1 e_k, each realization whitened by its own P_k, (K, d); None where P_k is shared
    whitened_error: np.ndarray | None = None
    whitened_outer: np.ndarray | None = None  #: sum eps_k eps_k^T, (K, d, d); None where P_k is shared
    whitened_estimate: np.ndarray | None = None  #: sum eps_k xhat_k^T, (K, d, d); None where P_k is shared
    #: the effect sizes' sums (:class:`kalcal.stats.effects.EffectLayout` lays them out), flat so that they
    #: merge, checkpoint and travel as every other sum; None for a problem that keeps none
    effect: np.ndarray | None = None
    #: counts of the NEES on :func:`shape_grid`'s bins per update, int64 (K, B); None for sums that did not
    #: keep it
    nees_histogram: np.ndarray | None = None
    nis_histogram: np.ndarray | None = None  #: counts of the NIS likewise, int64 (K, B)
    #: the effect sums per group of blocks, for the Cramér–Rao bound's own Monte Carlo error (a jackknife
    #: over the groups, :func:`kalcal.stats.effects.cramer_rao_bound`): ``((count, effect, mse), ...)`` in
    #: block order, ``effect`` the group's flat effect sums and ``mse`` its sum of e_ik^2, (K, d). Blocks are
    #: independent (each has its own SeedSequence stream); groups are kept of equal size but the last, and past
    #: :data:`EFFECT_GROUPS_MAX` groups adjacent pairs are folded into one (memory flat in N). None where a problem keeps no effect sums or the sums
    #: came from a checkpoint that did not keep them
    effect_blocks: tuple | None = None

    @classmethod
    def from_block(cls, block: BlockResult) -> MomentSums:
        """The sums of one block (n realizations); where P_k varies between them, the whitened sums too, and
        the pair sums of the innovations normalized by each realization's own S_k."""
        e = np.ascontiguousarray(block.error.transpose(1, 0, 2))  # (K, n, d)
        x = np.ascontiguousarray(block.estimate.transpose(1, 0, 2))
        n, n_updates, p = block.residual.shape
        own = not shares_cov(block.filter_cov)
        stacked = block.residual
        whitened = {}
        if own:
            eps = np.ascontiguousarray(whiten(block.filter_cov, block.error).transpose(1, 0, 2))  # (K, n, d)
            whitened = dict(
                whitened_error=eps.sum(axis=1),
                whitened_outer=np.swapaxes(eps, 1, 2) @ eps,
                whitened_estimate=np.swapaxes(eps, 1, 2) @ x,
            )
            stacked = _normalized(block)
        outer = ResidualProducts.upper(np.ascontiguousarray(stacked.reshape(n, n_updates * p).T))
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
            nees_histogram=shape_histogram(block.nees if block.shape_nees is None else block.shape_nees, block.error.shape[2]),
            nis_histogram=shape_histogram(block.nis if block.shape_nis is None else block.shape_nis, p),
            **whitened,
        )

    @classmethod
    def from_buffers(cls, count: int, buffers: SumBuffers, normalized_residual: np.ndarray | None = None) -> MomentSums:
        """The sums of ``count`` realizations that a kernel added into ``buffers`` (the pairs by syrk)."""
        sums = buffers._asdict()
        residuals = sums.pop("residuals")
        del sums["nees_grid"], sums["nis_grid"]
        outer = ResidualProducts.upper(residuals) if residuals.shape[0] else None
        for name in ("whitened_error", "whitened_outer", "whitened_estimate"):
            if not sums[name].shape[0]:  # P_k shared: derived from the raw sums
                sums[name] = None
        return cls(count=count, **sums, residual_outer=outer, normalized_residual=normalized_residual)

    def with_effect(self, flat: np.ndarray) -> MomentSums:
        """These sums (one block's) with their flat effect sums, kept also as the block's own group of
        :attr:`effect_blocks` with its count and its sum of e_ik^2 (the diagonal of ``error_outer``)."""
        self.effect = flat
        mse = np.diagonal(self.error_outer, axis1=1, axis2=2).copy()
        self.effect_blocks = ((self.count, flat.copy(), mse),)
        return self

    def merge(self, other: MomentSums) -> MomentSums:
        """The sums of both ensembles (self first, then other: the order fixes the rounding)."""
        def add(a, b):
            return None if a is None or b is None else a + b

        return MomentSums(
            count=self.count + other.count,
            **{f.name: add(getattr(self, f.name), getattr(other, f.name)) for f in fields(self)
               if f.name not in ("count", "effect_blocks")},
            effect_blocks=merge_effect_blocks(self.effect_blocks, other.effect_blocks),
        )


#: The most groups of blocks :attr:`MomentSums.effect_blocks` keeps: past it adjacent pairs are folded, so
#: the memory of the jackknife does not grow with N (between 32 and 64 groups of equal size: the
#: jackknife's variance estimate has 31 to 63 degrees of freedom, its standard error a relative error of
#: 1 / sqrt(2 x 31) = 13 % to 9 %).
EFFECT_GROUPS_MAX = 64


def merge_effect_blocks(a: tuple | None, b: tuple | None) -> tuple | None:
    """The groups of both (a's first, then b's, in block order), kept of equal size: each of b's groups fills a's
    last group while that is smaller than a's first (the full size), else starts a new one; past
    :data:`EFFECT_GROUPS_MAX` adjacent pairs are folded into one, doubling the full size. So every group but the
    last holds the same number of realizations (the delete-a-group jackknife's equal groups) whatever N. The
    engine merges in block order whatever its threads or Dask workers, so the groups (and the rounding of their
    sums) depend only on N, the block size and the seed."""
    if a is None or b is None:
        return None
    groups = list(a)
    for group in b:
        full = groups[0][0] if groups else group[0]
        last = groups[-1] if groups else None
        if last is not None and last[0] < full and last[0] + group[0] <= full:
            groups[-1] = (last[0] + group[0], last[1] + group[1], last[2] + group[2])
        else:
            groups.append(group)
        while len(groups) > EFFECT_GROUPS_MAX:
            folded = [
                (groups[i][0] + groups[i + 1][0], groups[i][1] + groups[i + 1][1], groups[i][2] + groups[i + 1][2])
                for i in range(0, len(groups) - 1, 2)
            ]
            if len(groups) % 2:
                folded.append(groups[-1])
            groups = folded
    return tuple(groups)


def _normalized(block: BlockResult) -> np.ndarray:
    """The innovations normalized by each realization's own S_k, (n, K, p): the block's
    ``normalized_residual`` where it has them, else, for scalar measurements, r / sqrt(S) =
    sign(r) sqrt(NIS)."""
    if block.normalized_residual is not None:
        return block.normalized_residual
    if block.residual.shape[2] != 1:
        raise ValueError("a block whose S_k varies needs its normalized innovations for the pair sums")
    return np.sign(block.residual) * np.sqrt(block.nis)[..., None]


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
    #: E[eps_k], eps_k = L_k^-1 e_k whitened by each realization's own P_k, (K, d); None where every
    #: realization shares P_k (the checks then whiten the raw moments by it)
    mean_whitened_error: np.ndarray | None = None
    whitened_second_moment: np.ndarray | None = None  #: E[eps_k eps_k^T], (K, d, d), or None as above
    whitened_estimate: np.ndarray | None = None  #: E[eps_k xhat_k^T], (K, d, d), or None as above
    #: counts of the NEES on :func:`shape_grid`'s bins per update, (K, B) (:class:`MomentSums`); None if not kept
    nees_histogram: np.ndarray | None = None
    nis_histogram: np.ndarray | None = None  #: counts of the NIS likewise, (K, B); None if not kept


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
        mean_whitened_error=None if sums.whitened_error is None else sums.whitened_error / n,
        whitened_second_moment=None if sums.whitened_outer is None else sums.whitened_outer / n,
        whitened_estimate=None if sums.whitened_estimate is None else sums.whitened_estimate / n,
        nees_histogram=sums.nees_histogram,
        nis_histogram=sums.nis_histogram,
    )
