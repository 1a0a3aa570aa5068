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
compiled, a fix costs about a microsecond, so an hour of 5 Hz fixes filters in milliseconds.

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
def _run(phis, qs, h, vs, z, x0, m0, threshold, states, covs, residuals, innovations, prior_states, prior_covs, rejected):
    n_fixes, d = states.shape
    x = x0.copy()
    cov = m0.copy()
    eye = np.eye(d)
    for k in range(n_fixes):
        x = phis[k] @ x
        cov = phis[k] @ cov @ phis[k].T + qs[k]
        cov = 0.5 * (cov + cov.T)
        prior_states[k] = x
        prior_covs[k] = cov
        present = True
        for i in range(z.shape[1]):
            if not np.isfinite(z[k, i]):
                present = False
        if not present:
            states[k] = x
            covs[k] = cov
            residuals[k] = np.nan
            innovations[k] = np.nan
            continue
        hm = h @ cov
        s = hm @ h.T + vs[k]
        s = 0.5 * (s + s.T)
        gain = np.linalg.solve(s, hm).T
        r = z[k] - h @ x
        if threshold < np.inf and r @ np.linalg.solve(s, r) > threshold:
            # gated out: kept for the record, filtered as a prediction only
            rejected[k] = True
            states[k] = x
            covs[k] = cov
            residuals[k] = r
            innovations[k] = s
            continue
        x = x + gain @ r
        i_kh = eye - gain @ h
        cov = i_kh @ cov @ i_kh.T + gain @ vs[k] @ gain.T
        cov = 0.5 * (cov + cov.T)
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
