"""The compiled accumulation of a block's moment sums and the small compiled helpers the block kernels share.

Both block kernels (:mod:`kalcal.montecarlo.kernels` for fixed gains, :mod:`kalcal.scenarios.scale_bias.kernels`
for data-dependent ones) keep one update's quantities of n realizations (the block, or a tile of it) as
structure of arrays (a state is (d, n), realizations innermost and contiguous) and hand them to
:func:`accumulate`, the compiled mirror of :meth:`kalcal.montecarlo.accumulators.MomentSums.from_block`:
the same sums, into the fields of a :class:`~kalcal.montecarlo.accumulators.SumBuffers`.

The reductions over realizations are compiled with reassociation allowed (so that they vectorize): a
given block on a given machine always gives the same bits, but a different CPU may round differently.
"""

from __future__ import annotations

import math

import numba


FAST = {"reassoc", "contract"}  #: the fast-math flags of the reductions over realizations


@numba.njit(nogil=True, cache=True, fastmath=FAST)
def affine(out, matrix, vectors, add):
    """out[a, :] = (add ? out[a, :] : 0) + sum_b matrix[a, b] vectors[b, :]  for (d, n) arrays."""
    rows, cols = matrix.shape
    n = vectors.shape[1]
    for a in range(rows):
        if not add:
            for i in range(n):
                out[a, i] = 0.0
        for b in range(cols):
            coef = matrix[a, b]
            if coef != 0.0:
                for i in range(n):
                    out[a, i] += coef * vectors[b, i]


@numba.njit(nogil=True, cache=True, fastmath=FAST)
def dot(u, v):
    """sum_i u_i v_i of two (n,) arrays."""
    acc = 0.0
    for i in range(u.shape[0]):
        acc += u[i] * v[i]
    return acc


@numba.njit(nogil=True, cache=True, fastmath=FAST)
def total(u):
    """sum_i u_i of an (n,) array: a loop, not ``ndarray.sum``, whose implementation lives in
    ``numba.np.arraymath``, a module that loads scipy.linalg when it is imported (0.3 s of a fresh
    process's first block, its kernels' environments rebuilt from the cache)."""
    acc = 0.0
    for i in range(u.shape[0]):
        acc += u[i]
    return acc


@numba.njit(nogil=True, cache=True)
def add_shape(k, values, scale, histogram):
    """Count each of the n ``values`` (n,) (NEES or NIS of n realizations at update k) into its bin of
    ``histogram[k]`` (K, B): min(floor(sqrt(x) scale), B - 1), 0 for x <= 0, B - 1 for NaN
    (:class:`~kalcal.montecarlo.accumulators.ShapeGrid`; the same floor of the same product as numpy's
    :func:`~kalcal.montecarlo.accumulators.shape_histogram`). Compiled without fast-math: the bins decide
    a count."""
    last = histogram.shape[1] - 1.0
    for i in range(values.shape[0]):
        x = values[i]
        where = math.sqrt(x if x > 0.0 else 0.0) * scale
        histogram[k, int(where if where < last else last) if x == x else int(last)] += 1


@numba.njit(nogil=True, cache=True, fastmath=FAST)
def whitened_squares(out, whitener, vectors, center, work):
    """out[i] = |W (v_i - c)|^2 for the n columns of ``vectors`` (q, n) and a center c (q,): each
    realization's NEES (W the state whitener of a shared P_k, W^T W = P_k^-1) or NIS about its predicted
    mean; ``work`` (q, n) is scratch."""
    affine(work, whitener, vectors, False)
    q, n = work.shape
    for a in range(q):
        shift = 0.0
        for b in range(q):
            shift += whitener[a, b] * center[b]
        if shift != 0.0:
            for i in range(n):
                work[a, i] -= shift
    for i in range(n):
        out[i] = 0.0
    for a in range(q):
        for i in range(n):
            out[i] += work[a, i] * work[a, i]


@numba.njit(nogil=True, cache=True, fastmath=FAST)
def accumulate(k, first, error, estimate, residual, nees, nis, cov, white, sums, store=True):
    """Add update k of n realizations into the sums (in place), as ``MomentSums.from_block`` sums them.

    Parameters
    ----------
    k : int
        The update, 0 <= k < K.
    first : int
        The block's index of the first of these n realizations (kernels that take the block in tiles
        call this once per tile and update).
    error, estimate : ndarray, shape (d, n)
        e_k = x_k - xhat_k and xhat_k of each realization.
    residual : ndarray, shape (p, n)
        r_k = z_k - H xbar_k; also copied into rows k p ... k p + p - 1, columns first ... first + n - 1
        of ``sums.residuals`` when that keeps the pairs and ``store`` is true (a kernel that forms the
        innovations in those rows passes False).
    nees, nis : ndarray, shape (n,) or (0,)
        Each realization's e^T P^{-1} e and r^T S^{-1} r, with ``cov`` (d, d, n) its P_k; all three empty
        (n = 0) where every realization shares P_k and S_k: the caller then forms the NEES and NIS sums
        from the second moments and the P sum as n P_k, and adds their histograms itself
        (:func:`add_shape`), and this adds nothing to them. Given, they are also counted into
        ``sums.nees_histogram`` and ``sums.nis_histogram``.
    white : ndarray, shape (d, n) or (0, n)
        eps_k = L_k^-1 e_k of each realization, by its own P_k = L_k L_k^T, added into the whitened sums
        where ``sums`` keeps them (P_k varies between realizations); empty where P_k is shared.
    sums : SumBuffers
    store : bool
        Copy the innovations into ``sums.residuals`` (when it keeps the pairs).
    """
    d, n = error.shape
    p = residual.shape[0]
    own = nees.shape[0] > 0
    for a in range(d):
        sums.error[k, a] += total(error[a])
        sums.estimate[k, a] += total(estimate[a])
        for b in range(d):
            sums.error_estimate[k, a, b] += dot(error[a], estimate[b])
            if b >= a:
                sums.error_outer[k, a, b] += dot(error[a], error[b])
                sums.estimate_outer[k, a, b] += dot(estimate[a], estimate[b])
                if own:
                    sums.filter_cov[k, a, b] += total(cov[a, b])
    for a in range(d):  # the symmetric sums: the lower triangle is the upper one
        for b in range(a):
            sums.error_outer[k, a, b] = sums.error_outer[k, b, a]
            sums.estimate_outer[k, a, b] = sums.estimate_outer[k, b, a]
            if own:
                sums.filter_cov[k, a, b] = sums.filter_cov[k, b, a]
    for a in range(p):
        sums.residual[k, a] += total(residual[a])
        for b in range(p):
            sums.residual_own[k, a, b] += dot(residual[a], residual[b])
        if store and sums.residuals.shape[0]:
            sums.residuals[k * p + a, first:first + n] = residual[a, :]
    if own:
        sums.nees[k] += total(nees)
        sums.nis[k] += total(nis)
        add_shape(k, nees, sums.nees_grid.scale, sums.nees_histogram)
        add_shape(k, nis, sums.nis_grid.scale, sums.nis_histogram)
    if white.shape[0] and sums.whitened_error.shape[0]:
        for a in range(d):
            sums.whitened_error[k, a] += total(white[a])
            for b in range(d):
                sums.whitened_estimate[k, a, b] += dot(white[a], estimate[b])
                if b >= a:
                    sums.whitened_outer[k, a, b] += dot(white[a], white[b])
        for a in range(d):
            for b in range(a):
                sums.whitened_outer[k, a, b] = sums.whitened_outer[k, b, a]
