"""The time-varying-regressor filter's block kernel: filter n series and sum, in one compiled pass (scale/bias).

numpy spends a block of the scale/bias Monte Carlo on stacked 2 x 2 products and 1 x 1 solves, a few
floating-point operations each behind a dispatch: about 0.2 ms per step for 4096 realizations. This
kernel runs the same recursion as :func:`kalcal.filters.regression.run_regression_filter` update by
update, each realization's state, covariance and gain in small scratch arrays, and hands each update's
errors, estimates, innovations, NEES, NIS and P of all realizations to
:func:`kalcal.montecarlo.sum_kernels.accumulate`. The numpy path stays as the oracle of the tests
(``ScaleBiasProblem.run_block`` + ``MomentSums.from_block``); both agree to rounding.

The filter step itself is compiled without fast-math (a realization's numbers are those of the numpy
recursion, operation for operation); only the sums over realizations are reassociated.
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
    """Realizations first ... first + m - 1 of :func:`regression_block_moments`, every update."""
    n_steps = y.shape[1]
    d = x0.shape[0]
    # one update's quantities of the tile's realizations, structure of arrays (realizations innermost)
    x = np.empty((d, m))
    cov = np.empty((d, d, m))
    err = np.empty((d, m))
    residual = np.empty((1, m))
    nees = np.empty(m)
    nis = np.empty(m)
    for j in range(m):
        for u in range(d):
            x[u, j] = x0[u]
            for v in range(d):
                cov[u, v, j] = cov0[u, v]
    ph = np.empty(d)
    gain = np.empty(d)
    a = np.empty((d, d))
    ap = np.empty((d, d))
    chol = np.empty((d, d))
    white = np.empty(d)
    for k in range(n_steps):
        for j in range(m):
            i = first + j
            for u in range(d):
                for v in range(d):
                    cov[u, v, j] += q[u, v]
            s = r
            res = y[i, k]
            for u in range(d):
                acc = 0.0
                for v in range(d):
                    acc += cov[u, v, j] * h[i, k, v]
                ph[u] = acc
            for u in range(d):
                s += h[i, k, u] * ph[u]
                res -= h[i, k, u] * x[u, j]
            for u in range(d):
                gain[u] = ph[u] / s
                x[u, j] += gain[u] * res
            if joseph:
                for u in range(d):
                    for v in range(d):
                        a[u, v] = (1.0 if u == v else 0.0) - gain[u] * h[i, k, v]
                for u in range(d):
                    for v in range(d):
                        acc = 0.0
                        for w in range(d):
                            acc += a[u, w] * cov[w, v, j]
                        ap[u, v] = acc
                for u in range(d):
                    for v in range(d):
                        acc = 0.0
                        for w in range(d):
                            acc += ap[u, w] * a[v, w]
                        cov[u, v, j] = acc + r * gain[u] * gain[v]
            else:
                for u in range(d):
                    for v in range(d):
                        cov[u, v, j] -= gain[u] * ph[v]
            for u in range(d):
                for v in range(u + 1, d):
                    mid = 0.5 * (cov[u, v, j] + cov[v, u, j])
                    cov[u, v, j] = mid
                    cov[v, u, j] = mid
            # e^T P^{-1} e through the Cholesky factor: |L^{-1} e|^2
            for u in range(d):
                err[u, j] = truth[i, k, u] - x[u, j]
            for u in range(d):
                acc = cov[u, u, j]
                for w in range(u):
                    acc -= chol[u, w] * chol[u, w]
                chol[u, u] = np.sqrt(acc)
                for v in range(u + 1, d):
                    acc = cov[v, u, j]
                    for w in range(u):
                        acc -= chol[v, w] * chol[u, w]
                    chol[v, u] = acc / chol[u, u]
            squares = 0.0
            for u in range(d):
                acc = err[u, j]
                for w in range(u):
                    acc -= chol[u, w] * white[w]
                white[u] = acc / chol[u, u]
                squares += white[u] * white[u]
            nees[j] = squares
            nis[j] = res * res / s
            residual[0, j] = res
        accumulate(k, first, err, x, residual, nees, nis, cov, sums)


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
        p = 1, added to (each realization's own P_k, NEES and NIS included)
    """
    n = y.shape[0]
    for first in range(0, n, TILE):
        _filter_tile(y, h, truth, x0, cov0, r, q, joseph, sums, first, min(TILE, n - first))
