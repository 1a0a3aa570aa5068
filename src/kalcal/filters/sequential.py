"""A compiled sequential Kalman filter for long logs: one predict and one Joseph update per fix.

It keeps each fix's prior (xbar_k, M_k) besides the posterior, for the RTS smoother
(:mod:`kalcal.core.smoother`).

The same equations as the reference steps :func:`kalcal.core.steps.predict` and
:func:`~kalcal.core.steps.update` in Joseph form (which the tests hold it equal to, fix by fix), for a
single realization with a transition, process noise and measurement noise of its own at every fix, and
the same convention for a missing measurement: a fix with a non-finite component is a prediction only
(posterior = prior, residual and S NaN). An optional innovation gate rejects a fix whose NIS
r_k^T S_k^{-1} r_k under its prior exceeds a threshold: that fix too is a prediction only, but its residual
and S (under the prior) are kept and it is marked in ``rejected``; with no threshold the numbers are those
of the ungated filter, operation for operation. numpy spends ~70 us per fix on the dozen tiny 3x3 products;
compiled as loops over preallocated scratch, a fix costs well under a microsecond, so an hour of 5 Hz fixes filters in milliseconds.

Its update (S, K and the Joseph-form P) is the package's one compiled covariance update,
:func:`kalcal.core.kernels.covariance_update`, on a tile of one realization, and its missing-measurement
test the compiled :func:`kalcal.core.kernels.measured`; tests/filters/test_sequential.py holds this filter
to the reference steps fix by fix.
"""

# numba cache stamp: kalcal.core.kernels a5dbbb626c1a87c1

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from kalcal.core.kernels import covariance_update, measured, update_work


class SequentialRun(NamedTuple):
    """K fixes, d states, p measurements."""

    state: np.ndarray  #: posterior x_k, (K, d)
    cov: np.ndarray  #: posterior P_k (Joseph form), (K, d, d)
    residual: np.ndarray  #: r_k = z_k - H xbar_k, (K, p)
    innovation_cov: np.ndarray  #: S_k, (K, p, p)
    prior_state: np.ndarray  #: xbar_k = Phi_k x_{k-1}, (K, d) (what a smoother needs)
    prior_cov: np.ndarray  #: M_k = Phi_k P_{k-1} Phi_k^T + Q_k, (K, d, d)


@numba.njit(cache=True, nogil=True)
def _solve_chol(lower, rhs, out):
    """out = S^{-1} rhs for S = L L^T (L lower, p x p; rhs p-vector): forward then back substitution."""
    p = lower.shape[0]
    for i in range(p):
        value = rhs[i]
        for j in range(i):
            value -= lower[i, j] * out[j]
        out[i] = value / lower[i, i]
    for i in range(p - 1, -1, -1):
        value = out[i]
        for j in range(i + 1, p):
            value -= lower[j, i] * out[j]
        out[i] = value / lower[i, i]


@numba.njit(cache=True, nogil=True)
def _run(phis, qs, h, vs, z, x0, m0, threshold, states, covs, residuals, innovations, prior_states, prior_covs, rejected):
    # Written as loops over preallocated scratch: the 3x3 and 2x2 products of one fix cost well under a
    # microsecond this way (array expressions allocate at every step). The update is the package's one
    # compiled covariance update on a tile of one realization (the trailing axis of length 1).
    n_fixes, d = states.shape
    p = z.shape[1]
    x = x0.copy()
    cov3 = np.empty((d, d, 1))
    cov3[:, :, 0] = m0
    cov = cov3[:, :, 0]
    h3 = np.empty((p, d, 1))
    h3[:, :, 0] = h
    tx, t1, t2 = np.empty(d), np.empty((d, d)), np.empty((d, d))
    gain3, s3, work = np.empty((p, d, 1)), np.empty((p, p, 1)), update_work(d, p, 1)
    lower, solved, r = work.lower[:, :, 0], np.empty(p), np.empty(p)
    for k in range(n_fixes):
        phi = phis[k]
        for a in range(d):  # xbar = Phi x
            value = 0.0
            for b in range(d):
                value += phi[a, b] * x[b]
            tx[a] = value
        x[:] = tx
        for a in range(d):  # M = Phi P Phi^T + Q, symmetrized
            for b in range(d):
                value = 0.0
                for c in range(d):
                    value += phi[a, c] * cov[c, b]
                t1[a, b] = value
        for a in range(d):
            for b in range(d):
                value = qs[k, a, b]
                for c in range(d):
                    value += t1[a, c] * phi[b, c]
                t2[a, b] = value
        for a in range(d):
            for b in range(d):
                cov[a, b] = 0.5 * (t2[a, b] + t2[b, a])
        prior_states[k] = x
        prior_covs[k] = cov
        if not measured(z[k], h):
            states[k] = x
            covs[k] = cov
            residuals[k] = np.nan
            innovations[k] = np.nan
            continue
        for i in range(p):  # r = z - H xbar
            value = z[k, i]
            for b in range(d):
                value -= h[i, b] * x[b]
            r[i] = value
        # S, K and the Joseph-form P, in place of M (kept in prior_covs[k] should the gate refuse the fix)
        covariance_update(cov3, h3, vs[k], True, gain3, s3, work)
        if threshold < np.inf:
            if p == 1:
                nis = r[0] * r[0] / s3[0, 0, 0]
            else:
                _solve_chol(lower, r, solved)
                nis = 0.0
                for i in range(p):
                    nis += r[i] * solved[i]
            if nis > threshold:  # gated out: kept for the record, filtered as a prediction only
                rejected[k] = True
                cov[:, :] = prior_covs[k]
                states[k] = x
                covs[k] = cov
                residuals[k] = r
                innovations[k] = s3[:, :, 0]
                continue
        for a in range(d):  # x = xbar + K r
            value = x[a]
            for i in range(p):
                value += gain3[i, a, 0] * r[i]
            x[a] = value
        states[k] = x
        covs[k] = cov
        residuals[k] = r
        innovations[k] = s3[:, :, 0]


def sequential_filter(
    phis: np.ndarray,
    qs: np.ndarray,
    h: np.ndarray,
    vs: np.ndarray,
    z: np.ndarray,
    x0: np.ndarray,
    m0: np.ndarray,
    *,
    threshold: float | None = None,
    rejected: np.ndarray | None = None,
) -> SequentialRun:
    """Filter one measurement sequence with per-fix models.

    Parameters
    ----------
    phis, qs : ndarray, shape (K, d, d)
        Transition and process-noise covariance from the previous fix (or the prior) to fix k.
    h : ndarray, shape (p, d)
    vs : ndarray, shape (K, p, p)
        Measurement-noise covariance of each fix.
    z : ndarray, shape (K, p)
        A fix with a non-finite component is missing: only predicted.
    x0, m0 : ndarray, shapes (d,), (d, d)
        Prior mean and covariance before the first fix.
    threshold : float, optional
        The innovation gate: a fix with r_k^T S_k^{-1} r_k > threshold is not used (prediction only); its
        residual and S stay in the run. None: no gate.
    rejected : ndarray of bool, shape (K,), optional
        Filled with the gate's rejections (False where a fix was used or missing).
    """
    n_fixes, d, p = z.shape[0], x0.shape[0], h.shape[0]
    states, covs = np.empty((n_fixes, d)), np.empty((n_fixes, d, d))
    residuals, innovations = np.empty((n_fixes, p)), np.empty((n_fixes, p, p))
    prior_states, prior_covs = np.empty((n_fixes, d)), np.empty((n_fixes, d, d))
    as_float = lambda a: np.ascontiguousarray(a, dtype=float)  # noqa: E731
    flags = np.zeros(n_fixes, dtype=np.bool_)
    limit = np.inf if threshold is None else float(threshold)
    _run(as_float(phis), as_float(qs), as_float(h), as_float(vs), as_float(z), as_float(x0), as_float(m0), limit, states, covs, residuals, innovations, prior_states, prior_covs, flags)
    if rejected is not None:
        rejected[...] = flags
    return SequentialRun(states, covs, residuals, innovations, prior_states, prior_covs)
