"""The one compiled covariance update (M to P, Joseph or standard form) that every compiled filter calls.

Every compiled path of the package that updates a covariance calls :func:`covariance_update`: the
sequential filter of a log (:mod:`kalcal.filters.sequential`), the data-dependent Monte Carlo block
kernel of a regression with data-dependent rows and the compiled diffuse likelihood of the
regression model's fit (tests/core/test_kernel_callers.py names each caller). It is the compiled twin of the covariance half of the
numpy reference :func:`kalcal.core.steps.gain_and_covariance`, with the same equations::

    S = H M H^T + V (symmetrized),   K = M H^T S^{-1},
    P = (I - K H) M (I - K H)^T + K V K^T   (joseph: its lower triangle, mirrored)   or   P = M - K H M   (standard, symmetrized).

It works on a tile of m realizations in structure of arrays (realizations on the last, contiguous axis:
a covariance is (d, d, m), a measurement matrix (p, d, m)), so that each line of it is a pass over the
tile that vectorizes; one realization is a tile of m = 1. The arrays are C-contiguous. K comes from a
Cholesky factor of S and two triangular solves (p > 1), or a division where p = 1: a scalar measurement
runs on arrays of one axis fewer (the regressor row (d, m), S (m,)), the loops the Monte Carlo kernel ran
before, so that its numbers stay the same bit for bit and its time the same to the measurement's noise
(the same equations indexed through the (p, d, m) arrays with loops over p = 1 measured 10-20% slower).
The functions are inlined into their callers: called, with reshaped views of the arrays, they cost the
log filter 4x and the likelihood 25x their time (a tile of one realization does a few dozen flops per
update); inlined, with views by indexing, the log filter runs as fast as its own loops did and the
likelihood in ~30 ns a sample (~16 ns before).
The fixed-gain block kernel (:mod:`kalcal.montecarlo.kernels`) does not call it: it applies gains computed
before any data and has no covariance to update.

:func:`diffuse_start` is the compiled twin of :func:`kalcal.core.diffuse.diffuse_start`, the information
filter's start for a diffuse state (Y = P^{-1} predicted and updated until it is nonsingular, then
P = Y^{-1}): the one compiled information update, which the compiled diffuse likelihood runs before its
covariance updates (tests/core/test_diffuse.py holds it to the reference).

:func:`measured` is the compiled twin of :func:`kalcal.core.missing.measured`, the one
missing-measurement rule: a measurement with a non-finite component (or a non-finite entry of its H) is
not used, and the step is a prediction only (the caller keeps P = M). The update itself assumes finite
inputs.

numba's cache and this module. A kernel that calls these functions compiles them into its own cached
machine code, and numba keys that cache on the caller's source file alone. Each caller therefore carries
a ``# numba cache stamp:`` line with the digest of this file, which tests/core/test_kernel_callers.py
holds to the present source: after a change here that test names each caller's new line, and the
renewed line makes numba compile the caller anew (docs/verification.md).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np


class UpdateWork(NamedTuple):
    """Scratch of :func:`covariance_update` for a tile of m realizations, d states, p measurements."""

    hm: np.ndarray  #: H M, (p, d, m) (computed as (M H^T)^T: the same numbers for a symmetric M)
    lower: np.ndarray  #: the Cholesky factor of S, (p, p, m); filled only where p > 1
    a: np.ndarray  #: I - K H, (d, d, m) (Joseph form, p = 1)
    ap: np.ndarray  #: (I - K H) M, (d, d, m) (Joseph form)
    acc: np.ndarray  #: one row of a tile, (m,)
    kv: np.ndarray  #: B H^T - K V, (p, d, m) as K^T is laid out (Joseph form, p > 1)
    #: where H may be nonzero, bool (p, d): all True from :func:`update_work`; a caller whose H has entries
    #: that are identically zero (a model's printed Jacobian) sets them False, and the products with them
    #: (exact zeros: the same sums) are skipped where p > 1
    h_nz: np.ndarray
    pivot: np.ndarray  #: the reciprocals of the Cholesky factor's diagonal, (p, m) (p > 1)
    #: where M may be nonzero, bool (d, d), symmetric: all True from :func:`update_work`; a caller whose M
    #: has entries that are identically zero (a state renewed by the prediction has no covariance with the
    #: states kept, where Q has none) sets them False, and H M skips the products with them where p > 1
    m_nz: np.ndarray
    #: the states whose rows of K and rows and columns of P the caller reads after the update, bool (d,):
    #: all True from :func:`update_work`; where p > 1, K's rows of the kept states alone are computed (the
    #: others hold what they held) and P's entries of two kept states alone are updated, the others keep M's values (a caller that never reads them: its next prediction and its
    #: statistics read only the kept states'); S and H M are whole whatever ``keep`` says
    keep: np.ndarray


@numba.njit(cache=True, nogil=True, inline="always")
def update_work(d, p, m):
    """The scratch :func:`covariance_update` needs, allocated once per tile (not once per update)."""
    return UpdateWork(np.empty((p, d, m)), np.empty((p, p, m)), np.empty((d, d, m)), np.empty((d, d, m)), np.empty(m),
                      np.empty((p, d, m)), np.ones((p, d), dtype=np.bool_), np.empty((p, m)),
                      np.ones((d, d), dtype=np.bool_), np.ones(d, dtype=np.bool_))


@numba.njit(cache=True, nogil=True, inline="always")
def measured(z, h):
    """True where every component of the measurement z (p,) and of its H (p, d) is finite."""
    for i in range(z.shape[0]):
        if not np.isfinite(z[i]):
            return False
    for i in range(h.shape[0]):
        for u in range(h.shape[1]):
            if not np.isfinite(h[i, u]):
                return False
    return True


@numba.njit(cache=True, nogil=True, inline="always")
def covariance_update(cov, h, v, joseph, gain, s, work):
    """The covariance half of a measurement update for a tile of m realizations, in place: M becomes P.

    Parameters
    ----------
    cov : ndarray, shape (d, d, m)
        The prior covariance M of each realization on input, its posterior P on output (symmetric).
    h : ndarray, shape (p, d, m)
        Each realization's measurement matrix H (a regressor row where p = 1).
    v : ndarray, shape (p, p)
        The measurement-noise covariance V, shared by the tile.
    joseph : bool
        The Joseph form; False: the standard form P = M - K H M.
    gain : ndarray, shape (p, d, m)
        Output: K^T = S^{-1} H M (the gain transposed, as H M is laid out: a scalar measurement's K is
        then one contiguous (d, m) row).
    s : ndarray, shape (p, p, m)
        Output: the innovation covariance S = H M H^T + V, symmetric.
    work : UpdateWork
        Scratch from :func:`update_work` (d, p, m); ``work.hm`` holds H M and, where p > 1,
        ``work.lower`` the Cholesky factor of S after the call (for a caller's NIS).
    """
    d, p, m = cov.shape[0], h.shape[0], cov.shape[2]
    hm, lower, a, ap, acc = work.hm, work.lower, work.a, work.ap, work.acc
    if p == 1:
        # the (d, m) rows of the (1, d, m) arrays, views by indexing (a reshape is a call per update)
        _scalar_update(cov, h[0], v[0, 0], joseph, gain[0], s[0, 0], hm[0], a, ap, acc)
    else:
        _general_update(cov, h, v, joseph, gain, s, hm, lower, a, ap, acc, work.kv, work.h_nz, work.pivot,
                        work.m_nz, work.keep)


@numba.njit(cache=True, nogil=True, inline="always")
def _general_update(cov, h, v, joseph, gain, s, hm, lower, a, ap, acc, kv, h_nz, pivot, m_nz, keep):
    """:func:`covariance_update` where p > 1: K by a Cholesky factor of S and two triangular solves.

    The Joseph form P = A M A^T + K V K^T (A = I - K H) by products of O(d^2 p) alone: B = A M =
    M - K (H M), then P = B A^T + K V K^T = B - (B H^T - K V) K^T, its lower triangle mirrored. The
    order keeps the factored form's numbers: B carries M's rounding, which A^T then multiplies (as the
    factored form's A, formed at the rounding of 1, does), so a huge prior against a precise measurement
    leaves P at K V K^T's scale (tests/core/test_kernel_update.py); the algebraically equal expansion
    M - (H M)^T K^T + K (S K^T - H M) sums terms of M's size and there loses P entirely. ``m_nz`` and
    ``keep`` (:class:`UpdateWork`) skip M's identically zero entries in H M and the states the caller does
    not read after the update."""
    d, p, m = cov.shape[0], h.shape[0], cov.shape[2]
    for i in range(p):  # H M, as (M H^T)^T, from its first product (zeros where every product is identically zero)
        for u in range(d):
            first = d
            for w in range(d - 1, -1, -1):
                if h_nz[i, w] and m_nz[u, w]:
                    first = w
            if first == d:
                for j in range(m):
                    hm[i, u, j] = 0.0
            else:
                for j in range(m):
                    hm[i, u, j] = cov[u, first, j] * h[i, first, j]
            for w in range(first + 1, d):
                if h_nz[i, w] and m_nz[u, w]:
                    for j in range(m):
                        hm[i, u, j] += cov[u, w, j] * h[i, w, j]
    for i in range(p):  # S = H M H^T + V
        for k in range(p):
            for j in range(m):
                s[i, k, j] = v[i, k]
            for u in range(d):
                if h_nz[k, u]:
                    for j in range(m):
                        s[i, k, j] += hm[i, u, j] * h[k, u, j]
    for i in range(p):
        for k in range(i):
            for j in range(m):
                mid = 0.5 * (s[i, k, j] + s[k, i, j])
                s[i, k, j] = mid
                s[k, i, j] = mid
    if p > 1:
        for i in range(p):  # S = L L^T
            for k in range(i + 1):
                for j in range(m):
                    acc[j] = s[i, k, j]
                for c in range(k):
                    for j in range(m):
                        acc[j] -= lower[i, c, j] * lower[k, c, j]
                for j in range(m):
                    lower[i, k, j] = np.sqrt(acc[j]) if i == k else acc[j] / lower[k, k, j]
            for k in range(i + 1, p):
                for j in range(m):
                    lower[i, k, j] = 0.0
            for j in range(m):  # the pivot's reciprocal: the solves below multiply (a division per lane
                pivot[i, j] = 1.0 / lower[i, i, j]  # and column costs several multiplications' time)
        for u in range(d):  # row u of K: S^{-1} (H M)[:, u], forward then back substitution (kept states')
            if not keep[u]:
                continue
            for j in range(m):
                gain[0, u, j] = hm[0, u, j] * pivot[0, j]
            for i in range(1, p):
                for j in range(m):
                    acc[j] = hm[i, u, j] - lower[i, 0, j] * gain[0, u, j]
                for c in range(1, i):
                    for j in range(m):
                        acc[j] -= lower[i, c, j] * gain[c, u, j]
                for j in range(m):
                    gain[i, u, j] = acc[j] * pivot[i, j]
            for j in range(m):
                gain[p - 1, u, j] = gain[p - 1, u, j] * pivot[p - 1, j]
            for i in range(p - 2, -1, -1):
                for j in range(m):
                    acc[j] = gain[i, u, j] - lower[i + 1, i, j] * gain[i + 1, u, j]
                for c in range(i + 2, p):
                    for j in range(m):
                        acc[j] -= lower[c, i, j] * gain[c, u, j]
                for j in range(m):
                    gain[i, u, j] = acc[j] * pivot[i, j]
    if joseph:
        # B = A M = M - K (H M), the kept states' rows, all columns (D below reads them all): the
        # cancellation of M against K H M (a huge prior, a precise measurement) leaves B at the rounding of
        # M, as A = I - K H is at the rounding of 1
        for u in range(d):
            if not keep[u]:
                continue
            for w in range(d):
                for j in range(m):
                    acc[j] = cov[u, w, j] - gain[0, u, j] * hm[0, w, j]
                for i in range(1, p):
                    for j in range(m):
                        acc[j] -= gain[i, u, j] * hm[i, w, j]
                for j in range(m):
                    ap[u, w, j] = acc[j]
        # D = B H^T - K V (p, d), as K^T is laid out: P = B A^T + K V K^T = B - D K^T, B's rounding
        # multiplied by A^T (the factored form's second factor) and K V K^T added at its own scale: the
        # Joseph form's numbers (a sum of the two symmetric terms), in O(d^2 p), not the expanded
        # M - K H M - M H^T K^T + K S K^T, whose terms of M's size leave P at M's rounding
        for i in range(p):
            for u in range(d):
                if not keep[u]:
                    continue
                for j in range(m):
                    acc[j] = 0.0
                for w in range(d):
                    if h_nz[i, w]:
                        for j in range(m):
                            acc[j] += ap[u, w, j] * h[i, w, j]
                for k in range(p):
                    for j in range(m):
                        acc[j] -= gain[k, u, j] * v[k, i]
                for j in range(m):
                    kv[i, u, j] = acc[j]
        # P = B - D K^T: its lower triangle, the kept states' entries, mirrored (symmetric by construction)
        for u in range(d):
            if not keep[u]:
                continue
            for w in range(u + 1):
                if keep[w]:
                    for j in range(m):
                        acc[j] = ap[u, w, j] - kv[0, u, j] * gain[0, w, j]
                    for i in range(1, p):
                        for j in range(m):
                            acc[j] -= kv[i, u, j] * gain[i, w, j]
                    for j in range(m):
                        cov[u, w, j] = acc[j]
        for u in range(d):
            if not keep[u]:
                continue
            for w in range(u):
                if keep[w]:
                    for j in range(m):
                        cov[w, u, j] = cov[u, w, j]
    else:
        for u in range(d):  # P = M - K (H M), the kept states' entries
            if not keep[u]:
                continue
            for w in range(d):
                if keep[w]:
                    for i in range(p):
                        for j in range(m):
                            cov[u, w, j] -= gain[i, u, j] * hm[i, w, j]
        for u in range(d):
            if not keep[u]:
                continue
            for w in range(u + 1, d):
                if keep[w]:
                    for j in range(m):
                        mid = 0.5 * (cov[u, w, j] + cov[w, u, j])
                        cov[u, w, j] = mid
                        cov[w, u, j] = mid


@numba.njit(cache=True, nogil=True, inline="always")
def _scalar_update(cov, h, r, joseph, gain, s, ph, a, ap, acc):
    """:func:`covariance_update` where p = 1: h a regressor row (d, m), r the variance V, S (m,), and
    K = M h^T / S by a division (``ph`` holds M h^T)."""
    d, m = h.shape
    for u in range(d):  # M h^T
        for j in range(m):
            acc[j] = 0.0
        for v in range(d):
            for j in range(m):
                acc[j] += cov[u, v, j] * h[v, j]
        for j in range(m):
            ph[u, j] = acc[j]
    for j in range(m):  # S = h M h^T + R
        s[j] = r
    for u in range(d):
        for j in range(m):
            s[j] += h[u, j] * ph[u, j]
    for u in range(d):  # K = M h^T / S
        for j in range(m):
            gain[u, j] = ph[u, j] / s[j]
    if joseph:
        for u in range(d):  # A = I - K h
            for v in range(d):
                eye = 1.0 if u == v else 0.0
                for j in range(m):
                    a[u, v, j] = eye - gain[u, j] * h[v, j]
        for u in range(d):  # A M
            for v in range(d):
                for j in range(m):
                    acc[j] = 0.0
                for w in range(d):
                    for j in range(m):
                        acc[j] += a[u, w, j] * cov[w, v, j]
                for j in range(m):
                    ap[u, v, j] = acc[j]
        for u in range(d):  # P = A M A^T + R K K^T
            for v in range(d):
                for j in range(m):
                    acc[j] = 0.0
                for w in range(d):
                    for j in range(m):
                        acc[j] += ap[u, w, j] * a[v, w, j]
                for j in range(m):
                    cov[u, v, j] = acc[j] + r * gain[u, j] * gain[v, j]
    else:
        for u in range(d):  # P = M - K (h M)
            for v in range(d):
                for j in range(m):
                    cov[u, v, j] -= gain[u, j] * ph[v, j]
    for u in range(d):
        for v in range(u + 1, d):
            for j in range(m):
                mid = 0.5 * (cov[u, v, j] + cov[v, u, j])
                cov[u, v, j] = mid
                cov[v, u, j] = mid


@numba.njit(cache=True, nogil=True)
def _eliminate(a, b):
    """Solve A X = B in place by Gaussian elimination with partial pivoting, for a small d x d A.

    ``b`` (d, n) becomes X and ``a`` is destroyed; returns det(A) (0.0 for a singular A, X then not
    to be used). A few dozen flops for d = 2 and no allocation: the diffuse start solves with it once
    a sample, where LAPACK's call would cost more than the sample."""
    d, n = a.shape[0], b.shape[1]
    det = 1.0
    for c in range(d):
        pivot = c
        for i in range(c + 1, d):
            if abs(a[i, c]) > abs(a[pivot, c]):
                pivot = i
        if pivot != c:
            det = -det
            for j in range(d):
                a[c, j], a[pivot, j] = a[pivot, j], a[c, j]
            for j in range(n):
                b[c, j], b[pivot, j] = b[pivot, j], b[c, j]
        det *= a[c, c]
        if a[c, c] == 0.0:
            return 0.0
        for i in range(c + 1, d):
            f = a[i, c] / a[c, c]
            for j in range(c, d):
                a[i, j] -= f * a[c, j]
            for j in range(n):
                b[i, j] -= f * b[c, j]
    for c in range(d - 1, -1, -1):
        for j in range(n):
            acc = b[c, j]
            for i in range(c + 1, d):
                acc -= a[c, i] * b[i, j]
            b[c, j] = acc / a[c, c]
    return det


@numba.njit(cache=True, nogil=True)
def diffuse_start(y, h, r, q, rcond, x, cov):
    """The information filter's start from a diffuse state, until the measurements determine it.

    The compiled twin of :func:`kalcal.core.diffuse.diffuse_start` (the numpy reference; the equations
    are in :mod:`kalcal.core.diffuse`), held to it by tests/core/test_diffuse.py: Y^- = (I + Q Y)^{-1} Y,
    y^- = (I + Q Y)^{-1} y (by a solve), Y += h_k^T h_k / R, y += h_k^T v_k / R, a missing measurement a
    prediction only (:func:`measured`), until det(Y) > rcond trace(Y)^d.

    Parameters
    ----------
    y : ndarray, shape (K,)
    h : ndarray, shape (K, d)
    r : float
    q : ndarray, shape (d, d)
    rcond : float
    x : ndarray, shape (d,)
        Output: x_m^+ = P_m y_m (untouched when the state is never determined).
    cov : ndarray, shape (d, d)
        Output: P_m^+ = Y_m^{-1}, symmetric (untouched when the state is never determined).

    Returns
    -------
    int
        m, the samples the start took; 0 when the measurements never determine the state.
    """
    n, d = h.shape
    info, vector = np.zeros((d, d)), np.zeros(d)
    a, b = np.empty((d, d)), np.empty((d, d + 1))
    value = np.empty(1)
    drift = False
    for i in range(d):
        for j in range(d):
            if q[i, j] != 0.0:
                drift = True
    for k in range(n):
        if drift:  # a = I + Q Y, b = [Y | y]: (I + Q Y)^{-1} [Y | y] by one elimination
            for i in range(d):
                for j in range(d):
                    acc = 1.0 if i == j else 0.0
                    for c in range(d):
                        acc += q[i, c] * info[c, j]
                    a[i, j] = acc
                    b[i, j] = info[i, j]
                b[i, d] = vector[i]
            _eliminate(a, b)
            for i in range(d):
                for j in range(d):
                    info[i, j] = 0.5 * (b[i, j] + b[j, i])
                vector[i] = b[i, d]
        value[0] = y[k]
        if not measured(value, h[k : k + 1]):  # the one missing-measurement rule: a prediction only
            continue
        for i in range(d):
            for j in range(d):
                info[i, j] += h[k, i] * h[k, j] / r
            vector[i] += h[k, i] * y[k] / r
        trace = 0.0
        for i in range(d):
            trace += info[i, i]
            for j in range(d):
                a[i, j] = info[i, j]
                b[i, j] = 1.0 if i == j else 0.0
            b[i, d] = 0.0
        det = _eliminate(a, b)  # b[:, :d] becomes Y^{-1}
        if det > rcond * trace**d:
            for i in range(d):
                for j in range(d):
                    cov[i, j] = 0.5 * (b[i, j] + b[j, i])
            for i in range(d):
                acc = 0.0
                for j in range(d):
                    acc += cov[i, j] * vector[j]
                x[i] = acc
            return k + 1
    return 0
