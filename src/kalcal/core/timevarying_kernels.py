"""The compiled filter and log-likelihood of a time-varying linear model, after its diffuse period.

The compiled twin of the proper (non-diffuse) rows of the numpy reference,
:func:`kalcal.core.timevarying_filter.reference_filter`, which tests/core/test_timevarying_filter.py holds
it to at every row. It takes the rows as the reference prepares them (:func:`kalcal.core.timevarying_filter.whiten`):
the measured components of row j decorrelated by the Cholesky factor L_j of V_j restricted to them, so that
row j is ``count[j]`` scalar measurements z*_{j,i} = h*_{j,i} x_j + e, e ~ N(0, 1), processed one at a time
(the univariate treatment of Koopman & Durbin 2000)::

    predict (row j-1 to j):  x = Phi x + B u_{j-1},   P = Phi P Phi^T + Gamma W Gamma^T  (symmetrized)
    update (each component): e = z* - h* x,  F = h* P h*^T + 1,  K = P h*^T / F,  x = x + K e,
                             P = (I - K h*) P (I - K h*)^T + K K^T       (Joseph form)
    log L += -1/2 (log 2 pi + log F + e^2 / F) - log L_ii

Each component's covariance update is the package's one compiled update,
:func:`kalcal.core.kernels.covariance_update`, on a tile of one realization (p = 1, v = 1).
The exact diffuse period (rows whose prior still has an infinite part) runs in numpy before it: it is a
few rows in any model whose diffuse states the first measurements determine.
"""

# numba cache stamp: kalcal.core.kernels a5dbbb626c1a87c1

from __future__ import annotations

import numba
import numpy as np

from kalcal.core.kernels import covariance_update, update_work

_LOG_2PI = float(np.log(2.0 * np.pi))


@numba.njit(cache=True, nogil=True)
def run_rows(phi, gq, bu, hs, zs, count, log_l, start, x0, p0, store, prior_states, prior_covs, states, covs):
    """Filter rows ``start``..J-1 from the prior (x0, p0) at row ``start``; return their log-likelihood.

    Parameters
    ----------
    phi : ndarray, shape (d, d)
    gq : ndarray, shape (d, d)
        Gamma W Gamma^T, the process-noise covariance per step.
    bu : ndarray, shape (J, d)
        B u_j, the known input's step from row j to row j + 1.
    hs : ndarray, shape (J, p, d)
        The decorrelated rows h*_{j,i}; the first ``count[j]`` of row j are its measured components.
    zs : ndarray, shape (J, p)
        The decorrelated measurements z*_{j,i} (dimensionless: unit variance).
    count : ndarray of int64, shape (J,)
    log_l : ndarray, shape (J, p)
        log L_ii, the Jacobian of the decorrelation of each component.
    start : int
        The first row to filter; its prior is (x0, p0), proper.
    x0 : ndarray, shape (d,)
    p0 : ndarray, shape (d, d)
    store : bool
        Write each row's prior and posterior into the four arrays (shape (J, ...)); False: the
        likelihood alone (the arrays may then have no rows).
    prior_states, prior_covs, states, covs : ndarray, shapes (J, d), (J, d, d), (J, d), (J, d, d)

    Returns
    -------
    float
        The sum of the rows' log-likelihood terms (natural log).
    """
    n, d = bu.shape
    x = x0.copy()
    cov3 = np.empty((d, d, 1))
    cov3[:, :, 0] = p0
    cov = cov3[:, :, 0]
    h3 = np.empty((1, d, 1))
    one = np.ones((1, 1))
    gain3, s3, work = np.empty((1, d, 1)), np.empty((1, 1, 1)), update_work(d, 1, 1)
    tx, t1, t2 = np.empty(d), np.empty((d, d)), np.empty((d, d))
    total = 0.0
    for j in range(start, n):
        if j > start:
            for a in range(d):  # x = Phi x + B u_{j-1}
                value = bu[j - 1, a]
                for b in range(d):
                    value += phi[a, b] * x[b]
                tx[a] = value
            x[:] = tx
            for a in range(d):  # P = Phi P Phi^T + Gamma W Gamma^T, symmetrized
                for b in range(d):
                    value = 0.0
                    for c in range(d):
                        value += phi[a, c] * cov[c, b]
                    t1[a, b] = value
            for a in range(d):
                for b in range(d):
                    value = gq[a, b]
                    for c in range(d):
                        value += t1[a, c] * phi[b, c]
                    t2[a, b] = value
            for a in range(d):
                for b in range(d):
                    cov[a, b] = 0.5 * (t2[a, b] + t2[b, a])
        if store:
            prior_states[j] = x
            prior_covs[j] = cov
        for i in range(count[j]):
            e = zs[j, i]
            for b in range(d):
                h3[0, b, 0] = hs[j, i, b]
                e -= hs[j, i, b] * x[b]
            covariance_update(cov3, h3, one, True, gain3, s3, work)
            f = s3[0, 0, 0]
            for a in range(d):
                x[a] += gain3[0, a, 0] * e
            total -= 0.5 * (_LOG_2PI + np.log(f) + e * e / f) + log_l[j, i]
        if store:
            states[j] = x
            covs[j] = cov
    return total
