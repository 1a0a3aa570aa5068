"""A compiled sequential Kalman filter for long logs: one predict and one Joseph update per fix.

It keeps each fix's prior (xbar_k, M_k) besides the posterior, for the RTS smoother
(:mod:`kalcal.filters.smoother`).

The same equations as the reference steps :func:`kalcal.filters.steps.predict` and
:func:`~kalcal.filters.steps.update` in Joseph form (which the tests hold it equal to, fix by fix), for a
single realization with a transition, process noise and measurement noise of its own at every fix, and
the same convention for a missing measurement: a fix with a non-finite component is a prediction only
(posterior = prior, residual and S NaN). An optional innovation gate rejects a fix whose NIS
r_k^T S_k^{-1} r_k under its prior exceeds a threshold: that fix too is a prediction only, but its residual
and S (under the prior) are kept and it is marked in ``rejected``; with no threshold the numbers are those
of the ungated filter, operation for operation. numpy spends ~70 us per fix on the dozen tiny 3x3 products;
compiled as loops over preallocated scratch, a fix costs well under a microsecond, so an hour of 5 Hz fixes filters in milliseconds.

Its Joseph update is written apart from the one of :mod:`kalcal.montecarlo.regression_kernels` (one
realization, a p-vector measurement, small matrix products here; tiles of realizations in structure of
arrays, a scalar measurement, there); tests/filters/test_sequential.py holds this one to the reference steps.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np


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
    # microsecond this way (array expressions allocate at every step). S is factored by Cholesky.
    n_fixes, d = states.shape
    p = z.shape[1]
    x, cov = x0.copy(), m0.copy()
    tx, t1, t2 = np.empty(d), np.empty((d, d)), np.empty((d, d))
    hm, s, lower = np.empty((p, d)), np.empty((p, p)), np.empty((p, p))
    gain, column, solved, r = np.empty((d, p)), np.empty(p), np.empty(p), np.empty(p)
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
        present = True
        for i in range(p):
            if not np.isfinite(z[k, i]):
                present = False
        if not present:
            states[k] = x
            covs[k] = cov
            residuals[k] = np.nan
            innovations[k] = np.nan
            continue
        for i in range(p):  # H M and S = H M H^T + V
            for a in range(d):
                value = 0.0
                for b in range(d):
                    value += h[i, b] * cov[b, a]
                hm[i, a] = value
        for i in range(p):
            for j in range(p):
                value = vs[k, i, j]
                for a in range(d):
                    value += hm[i, a] * h[j, a]
                s[i, j] = value
        for i in range(p):
            for j in range(i):
                s[i, j] = s[j, i] = 0.5 * (s[i, j] + s[j, i])
        for i in range(p):  # S = L L^T
            for j in range(i + 1):
                value = s[i, j]
                for c in range(j):
                    value -= lower[i, c] * lower[j, c]
                lower[i, j] = np.sqrt(value) if i == j else value / lower[j, j]
            for j in range(i + 1, p):
                lower[i, j] = 0.0
        for i in range(p):  # r = z - H xbar
            value = z[k, i]
            for b in range(d):
                value -= h[i, b] * x[b]
            r[i] = value
        if threshold < np.inf:
            _solve_chol(lower, r, solved)
            nis = 0.0
            for i in range(p):
                nis += r[i] * solved[i]
            if nis > threshold:  # gated out: kept for the record, filtered as a prediction only
                rejected[k] = True
                states[k] = x
                covs[k] = cov
                residuals[k] = r
                innovations[k] = s
                continue
        for a in range(d):  # K = M H^T S^{-1}, one row at a time (S^{-1} (H M)[:, a])
            for i in range(p):
                column[i] = hm[i, a]
            _solve_chol(lower, column, solved)
            for i in range(p):
                gain[a, i] = solved[i]
        for a in range(d):  # x = xbar + K r
            value = x[a]
            for i in range(p):
                value += gain[a, i] * r[i]
            x[a] = value
        for a in range(d):  # Joseph: (I - K H) M (I - K H)^T + K V K^T
            for b in range(d):
                value = 1.0 if a == b else 0.0
                for i in range(p):
                    value -= gain[a, i] * h[i, b]
                t1[a, b] = value
        for a in range(d):
            for b in range(d):
                value = 0.0
                for c in range(d):
                    value += t1[a, c] * cov[c, b]
                t2[a, b] = value
        for a in range(d):
            for b in range(d):
                value = 0.0
                for c in range(d):
                    value += t2[a, c] * t1[b, c]
                for i in range(p):
                    for j in range(p):
                        value += gain[a, i] * vs[k, i, j] * gain[b, j]
                cov[a, b] = value
        for a in range(d):
            for b in range(a):
                cov[a, b] = cov[b, a] = 0.5 * (cov[a, b] + cov[b, a])
        states[k] = x
        covs[k] = cov
        residuals[k] = r
        innovations[k] = s


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
