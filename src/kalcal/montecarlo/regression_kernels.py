"""The time-varying-regressor filter's block kernel: filter n series and sum, in one compiled pass (scale/bias).

numpy spends a block of the scale/bias Monte Carlo on stacked 2 x 2 products and 1 x 1 solves, a few
floating-point operations each behind a dispatch: about 0.2 ms per step for 4096 realizations. This
kernel runs the same recursion as :func:`kalcal.filters.regression.run_regression_filter` for a tile of
realizations at a time, update by update, each line of it one pass over the tile (structure of arrays:
realizations innermost, so that the passes vectorize), and hands each update's errors, estimates,
innovations, NEES, NIS, P and whitened errors L_k^-1 e_k of the tile to :func:`kalcal.montecarlo.sum_kernels.accumulate`. The numpy
path stays as the oracle of the tests (``ScaleBiasProblem.run_block`` + ``MomentSums.from_block``); both
agree to rounding, and tests/montecarlo/test_kernel_steps.py holds the recursion to the regression filter
update by update. It has no missing-measurement rule: the Monte Carlo never feeds it a NaN (its
measurements and regressors are simulated, always finite).

Its Joseph update is written apart from the one of :mod:`kalcal.filters.sequential` (one realization,
small matrix products there; tiles of realizations in structure of arrays, scalar measurement, here);
tests/montecarlo/test_kernel_steps.py holds this one to the reference steps through the regression filter.

The filter step itself is compiled without fast-math (each realization's numbers are the same on every
machine and in any tile); only the sums over realizations are reassociated.
"""

from __future__ import annotations

import numba
import numpy as np

from kalcal.montecarlo.sum_kernels import accumulate

#: realizations filtered together, update by update: their inputs (strided by K in the (n, K) layout)
#: stay in the cache from one update to the next
TILE = 256


@numba.njit(nogil=True, cache=True)
def _filter_tile(y, h, truth, x0, cov0, r, q, joseph, sums, first, m):
    """Realizations first ... first + m - 1 of :func:`regression_block_moments`, every update.

    Each line of the recursion is a pass over the tile's m realizations (the innermost, contiguous
    axis), so that it vectorizes.
    """
    n_steps = y.shape[1]
    d = x0.shape[0]
    x = np.empty((d, m))  # x^+, P^+ of each realization, carried from update to update
    cov = np.empty((d, d, m))
    for u in range(d):
        x[u, :] = x0[u]
        for v in range(d):
            cov[u, v, :] = cov0[u, v]
    hk = np.empty((d, m))  # this update's regressors and true states, gathered from the (n, K) layout
    err = np.empty((d, m))
    residual = np.empty((1, m))
    res = residual[0]
    s = np.empty(m)
    nees = np.empty(m)
    nis = np.empty(m)
    acc = np.empty(m)
    ph = np.empty((d, m))
    gain = np.empty((d, m))
    a = np.empty((d, d, m))
    ap = np.empty((d, d, m))
    chol = np.empty((d, d, m))
    white = np.empty((d, m))
    for k in range(n_steps):
        for j in range(m):
            i = first + j
            res[j] = y[i, k]
            for u in range(d):
                hk[u, j] = h[i, k, u]
                err[u, j] = truth[i, k, u]
        for u in range(d):  # P^- = P^+ + Q
            for v in range(d):
                for j in range(m):
                    cov[u, v, j] += q[u, v]
        for u in range(d):  # P^- h^T
            for j in range(m):
                acc[j] = 0.0
            for v in range(d):
                for j in range(m):
                    acc[j] += cov[u, v, j] * hk[v, j]
            ph[u, :] = acc
        for j in range(m):
            s[j] = r
        for u in range(d):  # S = h P^- h^T + R, r = y - h x^-
            for j in range(m):
                s[j] += hk[u, j] * ph[u, j]
                res[j] -= hk[u, j] * x[u, j]
        for u in range(d):  # K = P^- h^T / S, x^+ = x^- + K r
            for j in range(m):
                gain[u, j] = ph[u, j] / s[j]
                x[u, j] += gain[u, j] * res[j]
        if joseph:
            for u in range(d):  # A = I - K h
                for v in range(d):
                    eye = 1.0 if u == v else 0.0
                    for j in range(m):
                        a[u, v, j] = eye - gain[u, j] * hk[v, j]
            for u in range(d):  # A P^-
                for v in range(d):
                    for j in range(m):
                        acc[j] = 0.0
                    for w in range(d):
                        for j in range(m):
                            acc[j] += a[u, w, j] * cov[w, v, j]
                    ap[u, v, :] = acc
            for u in range(d):  # P^+ = A P^- A^T + R K K^T
                for v in range(d):
                    for j in range(m):
                        acc[j] = 0.0
                    for w in range(d):
                        for j in range(m):
                            acc[j] += ap[u, w, j] * a[v, w, j]
                    for j in range(m):
                        cov[u, v, j] = acc[j] + r * gain[u, j] * gain[v, j]
        else:
            for u in range(d):  # P^+ = P^- - K (h P^-)
                for v in range(d):
                    for j in range(m):
                        cov[u, v, j] -= gain[u, j] * ph[v, j]
        for u in range(d):
            for v in range(u + 1, d):
                for j in range(m):
                    mid = 0.5 * (cov[u, v, j] + cov[v, u, j])
                    cov[u, v, j] = mid
                    cov[v, u, j] = mid
        for u in range(d):  # e = x - x^+
            for j in range(m):
                err[u, j] -= x[u, j]
        # e^T P^{-1} e through the Cholesky factor: |L^{-1} e|^2
        for u in range(d):
            acc[:] = cov[u, u]
            for w in range(u):
                for j in range(m):
                    acc[j] -= chol[u, w, j] * chol[u, w, j]
            for j in range(m):
                chol[u, u, j] = np.sqrt(acc[j])
            for v in range(u + 1, d):
                acc[:] = cov[v, u]
                for w in range(u):
                    for j in range(m):
                        acc[j] -= chol[v, w, j] * chol[u, w, j]
                for j in range(m):
                    chol[v, u, j] = acc[j] / chol[u, u, j]
        nees[:] = 0.0
        for u in range(d):
            acc[:] = err[u]
            for w in range(u):
                for j in range(m):
                    acc[j] -= chol[u, w, j] * white[w, j]
            for j in range(m):
                white[u, j] = acc[j] / chol[u, u, j]
                nees[j] += white[u, j] * white[u, j]
        for j in range(m):
            nis[j] = res[j] * res[j] / s[j]
        accumulate(k, first, err, x, residual, nees, nis, cov, white, sums, False)
        if sums.residuals.shape[0]:
            # the pairs of the normalized innovations r / sqrt(S): each realization has its own S_k, and
            # only these are N(0, 1) and independent across updates for every realization alike
            for j in range(m):
                sums.residuals[k, first + j] = res[j] / np.sqrt(s[j])


@numba.njit(nogil=True, cache=True)
def regression_block_moments(y, h, truth, x0, cov0, r, q, joseph, sums):
    """Filter n series of K scalar measurements and add their moments into the sums (in place).

    Each step: P^- = P^+ + Q; S = h P^- h^T + R; K = P^- h^T / S; x^+ = x^- + K (y - h x^-);
    P^+ = (I - K h) P^- (I - K h)^T + R K K^T (``joseph``) or P^- - K (h P^-), then symmetrized.

    Parameters
    ----------
    y : (n, K) measurements; h : (n, K, d) regressor rows; truth : (n, K, d) true states
    x0 : (d,) x_0^+; cov0 : (d, d) P_0^+; r : float R; q : (d, d) Q per step; joseph : bool
    sums : the block's :class:`~kalcal.montecarlo.accumulators.SumBuffers` for K updates, d states and
        p = 1, added to (each realization's own P_k, NEES and NIS included, the whitened errors
        L_k^-1 e_k where it keeps them, and the normalized innovations r_k / sqrt(S_k) for the pairs)
    """
    n = y.shape[0]
    for first in range(0, n, TILE):
        _filter_tile(y, h, truth, x0, cov0, r, q, joseph, sums, first, min(TILE, n - first))
