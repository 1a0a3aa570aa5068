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

Its covariance update (S, K and P^+, Joseph or standard form) is the package's one compiled update,
:func:`kalcal.core.kernels.covariance_update`, on the tile as it lies (p = 1: K by a division);
tests/montecarlo/test_kernel_steps.py holds this kernel to the reference steps through the regression
filter, and tests/core/test_kernel_update.py the update itself to :func:`kalcal.core.steps.gain_and_covariance`.

The filter step itself is compiled without fast-math (each realization's numbers are the same on every
machine and in any tile); only the sums over realizations are reassociated.
"""

# numba cache stamp: kalcal.core.kernels a5dbbb626c1a87c1, kalcal.montecarlo.sum_kernels 1ed5637ca40b0768

from __future__ import annotations

import numba
import numpy as np

from kalcal.core.kernels import covariance_update, update_work
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
    hk3 = np.empty((1, d, m))  # this update's regressor rows (as the (p, d, m) H of p = 1) and true states,
    hk = hk3[0]  # gathered from the (n, K) layout
    err = np.empty((d, m))
    residual = np.empty((1, m))
    res = residual[0]
    s3 = np.empty((1, 1, m))
    s = s3[0, 0]
    gain3 = np.empty((1, d, m))
    work = update_work(d, 1, m)
    rv = np.full((1, 1), r)
    nees = np.empty(m)
    nis = np.empty(m)
    acc = np.empty(m)
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
        for u in range(d):  # r = y - h x^-
            for j in range(m):
                res[j] -= hk[u, j] * x[u, j]
        # S, K and P^+ (Joseph or standard form): the one compiled covariance update
        covariance_update(cov, hk3, rv, joseph, gain3, s3, work)
        for u in range(d):  # x^+ = x^- + K r
            for j in range(m):
                x[u, j] += gain3[0, u, j] * res[j]
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
