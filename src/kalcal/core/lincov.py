"""The exact first and second moments of a fixed-gain filter's errors and innovations against a linear truth.

No sampling: the truth and the filter's estimate are jointly Gaussian, and their mean and covariance
follow a linear recursion (covariance analysis, Gelb ch. 7; Maybeck vol. 1 ch. 6). The truth is that
of :mod:`kalcal.simulation.exact`, written with explicit covariances (d_t truth states, p measurements,
K updates)::

    y_0 ~ N(x0_mean, M0),   u_0 ~ N(0, s_u)
    y_{k+1} = A_k y_k + q_k + b_in u_k + b_out u_{k+1},   q_k ~ N(0, Q),  u_k ~ N(0, s_u)
    x_k = y_{k+1} + D_k,    z_k = H_t x_k + eta_k,          eta_k ~ N(0, R)

The boundary sample u shared by neighbouring intervals (the trapezoid rule) is carried as one extra
truth state, s = [y; u], so the recursion stays exact. The filter (d_f states) runs with fixed gains::

    xbar_k = Phi_k xhat_{k-1},   r_k = z_k - H_f xbar_k,   xhat_k = xbar_k + K_k r_k,   xhat_{-1} = x0

and its error is e_k = M x_k - xhat_k for a (d_f, d_t) map M (identity when the filter models every
truth state). The joint state carried is J_k = [s_{k+1}; e~_k] with e~_k = e_k - M D_k: in these
coordinates a correct filter's error decouples from the (much larger) truth state, so P_true keeps
every digit of the Riccati P.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from kalcal.linalg import symmetrize


@dataclass(frozen=True)
class TruthArrays:
    """The truth of the module docstring as explicit arrays. d_t states, p measurements, K updates."""

    transitions: np.ndarray  #: A_k, (K, d_t, d_t)
    #: Q, the interval's noise apart from the boundary sample, (d_t, d_t), or Q_k per update (K, d_t, d_t)
    process_cov: np.ndarray
    boundary_in: np.ndarray  #: b_in, (d_t,)
    boundary_out: np.ndarray  #: b_out, (d_t,)
    boundary_var: float  #: s_u, variance of the shared boundary sample (1, or 0 to switch it off)
    model_error: np.ndarray  #: D_k, (K, d_t)
    x0_mean: np.ndarray  #: (d_t,)
    prior_cov: np.ndarray  #: M0, (d_t, d_t)
    h: np.ndarray  #: H_t, (p, d_t), or H_t,k per update (K, p, d_t)
    measurement_cov: np.ndarray  #: R, (p, p), or R_k per update (K, p, p)

    @property
    def shares_boundary(self) -> bool:
        """Whether a boundary sample is carried as a state (b_in or b_out nonzero)."""
        return bool(np.any(self.boundary_in != 0.0) or np.any(self.boundary_out != 0.0))


@dataclass(frozen=True)
class FilterArrays:
    """A fixed-gain filter. d_f states, p measurements, K updates."""

    transitions: np.ndarray  #: Phi_k, (K, d_f, d_f)
    h: np.ndarray  #: H_f, (p, d_f), or H_f,k per update (K, p, d_f)
    gain: np.ndarray  #: K_k, (K, d_f, p)
    x0: np.ndarray  #: xhat_{-1}, (d_f,)


@dataclass(frozen=True)
class Moments:
    """Exact moments at every update (raw second moments, as the Monte Carlo sums keep them)."""

    mean_error: np.ndarray  #: E[e_k], (K, d_f)
    error_cov: np.ndarray  #: Cov(e_k), centered, (K, d_f, d_f)
    mean_estimate: np.ndarray  #: E[xhat_k], (K, d_f)
    error_estimate: np.ndarray  #: E[e_k xhat_k^T], (K, d_f, d_f)
    mean_residual: np.ndarray  #: E[r_k], (K, p)
    residual_cov: np.ndarray  #: Cov(r_k), (K, p, p)
    residual_second_moment: np.ndarray | None  #: E[r_k r_j^T] for every pair, (K, p, K, p), or None
    estimate_cov: np.ndarray | None = None  #: Cov(xhat_k), centered, (K, d_f, d_f)


@dataclass(frozen=True)
class _Recursion:
    """The joint recursion J_k = T_k J_{k-1} + B_k n_k + c_k and r_k = R_k J_{k-1} + Bz n_k + Ht D_k."""

    t: np.ndarray  #: (K, n, n)
    b: np.ndarray  #: (K, n, n_in)
    r: np.ndarray  #: (K, p, n)
    bz: np.ndarray  #: (K, p, n_in)
    project: np.ndarray  #: P_M = M E_y, (d_f, d_s)
    d_s: int


def _recursion(truth: TruthArrays, filt: FilterArrays, error_map: np.ndarray | None) -> _Recursion:
    """The matrices of the joint recursion over J = [s; e~], with Z_k = I - K_k H_f and P_M = M E_y::

        s_{k+1} = F_k s_k + N w_k                      (w_k = [q_k; u_{k+1}])
        e~_k    = (P_M - K_k H_t E_y) s_{k+1} - Z_k Phi_k P_M s_k + Z_k Phi_k e~_{k-1} - K_k eta_k - K_k H_t D_k
        r_k     = (H_t E_y F_k - H_f Phi_k P_M) s_k + H_f Phi_k e~_{k-1} + H_t E_y N w_k + eta_k + H_t D_k

    from xhat_{k-1} = P_M s_k - e~_{k-1}. For a correct filter (M = I, H_t = H_f, A_k = Phi_k) the
    weight of s_k in e~_k and r_k vanishes, so the error does not pass through the truth's own spread.
    """
    a = np.asarray(truth.transitions, dtype=float)
    n_updates, d_t, _ = a.shape
    d_f = filt.h.shape[-1]
    p = truth.h.shape[-2]
    c = int(truth.shares_boundary)
    d_s = d_t + c
    m = np.eye(d_t) if error_map is None else np.asarray(error_map, dtype=float)
    if m.shape != (d_f, d_t):
        raise ValueError(f"error_map: expected shape {(d_f, d_t)}, got {m.shape}")
    e_y = np.eye(d_t, d_s)
    project = m @ e_y
    ht = truth.h @ e_y  # (p, d_s), or (K, p, d_s) for rows that change from update to update
    # s_{k+1} = F_k s_k + N [q; u_{k+1}]
    f = np.zeros((n_updates, d_s, d_s))
    f[:, :d_t, :d_t] = a
    noise = np.eye(d_s)
    if c:
        f[:, :d_t, d_t] = truth.boundary_in
        noise[:d_t, d_t] = truth.boundary_out
    gain, phi = np.asarray(filt.gain, dtype=float), np.asarray(filt.transitions, dtype=float)
    closed = (np.eye(d_f) - gain @ filt.h) @ phi  # Z_k Phi_k, (K, d_f, d_f)
    w = project - gain @ ht  # e~_k's weight on s_{k+1}, (K, d_f, d_s)
    n = d_s + d_f
    t = np.zeros((n_updates, n, n))
    t[:, :d_s, :d_s] = f
    t[:, d_s:, :d_s] = w @ f - closed @ project
    t[:, d_s:, d_s:] = closed
    b = np.zeros((n_updates, n, d_s + p))
    b[:, :d_s, :d_s] = noise
    b[:, d_s:, :d_s] = w @ noise
    b[:, d_s:, d_s:] = -gain
    h_phi = filt.h @ phi  # (K, p, d_f)
    r = np.concatenate([ht @ f - h_phi @ project, h_phi], axis=-1)
    bz = np.concatenate([np.broadcast_to(ht @ noise, (n_updates, p, d_s)), np.broadcast_to(np.eye(p), (n_updates, p, p))], axis=-1)
    return _Recursion(t, b, r, bz, project, d_s)


def _input_cov(truth: TruthArrays) -> np.ndarray:
    """Covariance of each interval's inputs [q; u_{k+1}; eta_k], (K, n_in, n_in) (Q and R may change from
    update to update)."""
    n_updates, d_t = truth.transitions.shape[0], truth.transitions.shape[-1]
    c = int(truth.shares_boundary)
    blocks = [np.asarray(truth.process_cov, dtype=float)]
    if c:
        blocks.append(np.array([[float(truth.boundary_var)]]))
    blocks.append(np.asarray(truth.measurement_cov, dtype=float))
    size = d_t + c + truth.h.shape[-2]
    cov = np.zeros((n_updates, size, size))
    at = 0
    for block in blocks:
        width = block.shape[-1]
        cov[:, at : at + width, at : at + width] = block
        at += width
    return cov


def _initial(truth: TruthArrays, filt: FilterArrays, rec: _Recursion) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of J_{-1} = [s_0; M y_0 - x0]."""
    d_t = truth.transitions.shape[-1]
    d_s = rec.d_s
    s_cov = np.zeros((d_s, d_s))
    s_cov[:d_t, :d_t] = truth.prior_cov
    if d_s > d_t:
        s_cov[d_t, d_t] = truth.boundary_var
    s_mean = np.zeros(d_s)
    s_mean[:d_t] = truth.x0_mean
    lift = np.vstack([np.eye(d_s), rec.project])  # J_{-1} = lift s_0 - [0; x0]
    mean = lift @ s_mean - np.concatenate([np.zeros(d_s), filt.x0])
    return mean, lift @ s_cov @ lift.T


def _covariances(rec: _Recursion, initial: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """Cov(e~_k) for a stack of S initial covariances (S, n, n) and input covariances (S, K, n_in, n_in)."""
    n_updates, d_s = rec.t.shape[0], rec.d_s
    out = np.empty((initial.shape[0], n_updates, rec.project.shape[0], rec.project.shape[0]))
    cov = initial
    for k in range(n_updates):
        t = rec.t[k]
        cov = symmetrize(t @ cov @ t.T + rec.b[k] @ sigma[:, k] @ rec.b[k].T)
        out[:, k] = cov[:, d_s:, d_s:]
    return out


def error_covariance(truth: TruthArrays, filt: FilterArrays, error_map: np.ndarray | None = None) -> np.ndarray:
    """Cov(e_k) = P_true alone, (K, d_f, d_f)."""
    return source_covariances(truth, filt, [truth], error_map)[0]


def source_covariances(
    truth: TruthArrays, filt: FilterArrays, shares: Sequence[TruthArrays], error_map: np.ndarray | None = None
) -> np.ndarray:
    """Cov(e_k) for each of S truths that differ from ``truth`` only in (M0, Q, s_u, R), in one pass.

    Cov(e_k) is linear in those four with the gains fixed; the recursion's matrices are ``truth``'s.

    Returns
    -------
    ndarray, shape (S, K, d_f, d_f)
    """
    rec = _recursion(truth, filt, error_map)
    initial = np.stack([_initial(share, filt, rec)[1] for share in shares])
    sigma = np.stack([_input_cov(share) for share in shares])
    return _covariances(rec, initial, sigma)


def propagate(
    truth: TruthArrays, filt: FilterArrays, error_map: np.ndarray | None = None, *, pairs: bool = True
) -> Moments:
    """Every exact moment of the filter's errors, estimates and innovations at every update.

    Parameters
    ----------
    truth : TruthArrays
    filt : FilterArrays
    error_map : ndarray, shape (d_f, d_t), optional
        M in e = M x - xhat; None is the identity (d_f = d_t).
    pairs : bool
        Also E[r_k r_j^T] over every pair of updates (O(K) products of (n, n) by (n, K p)).

    Returns
    -------
    Moments
        E[e_k] (the filter's response to the truth's mean: prior-mean offset and model error D_k),
        Cov(e_k) = P_true, E[xhat_k], E[e_k xhat_k^T], E[r_k], Cov(r_k) and E[r_k r_j^T].
    """
    rec = _recursion(truth, filt, error_map)
    mean, cov = _initial(truth, filt, rec)
    sigma = _input_cov(truth)
    n_updates, p, n = rec.r.shape
    d_s, d_f = rec.d_s, filt.h.shape[-1]
    m_d = np.asarray(truth.model_error) @ rec.project[:, : truth.transitions.shape[-1]].T  # M D_k, (K, d_f)
    h_t, model_error = np.asarray(truth.h), np.asarray(truth.model_error)
    hd = model_error @ h_t.T if h_t.ndim == 2 else np.einsum("kij,kj->ki", h_t, model_error)  # H_t D_k, (K, p)
    mean_error = np.empty((n_updates, d_f))
    error_cov = np.empty((n_updates, d_f, d_f))
    mean_estimate = np.empty((n_updates, d_f))
    error_estimate = np.empty((n_updates, d_f, d_f))
    estimate_cov = np.empty((n_updates, d_f, d_f))
    mean_residual = np.empty((n_updates, p))
    residual_cov = np.empty((n_updates, p, p))
    cross = np.zeros((n, n_updates * p))  # Cov(J_k, r_j) for j <= k, column block j
    pair_cov = np.zeros((n_updates, p, n_updates, p)) if pairs else None
    for k in range(n_updates):
        t, b, r, bz, sig = rec.t[k], rec.b[k], rec.r[k], rec.bz[k], sigma[k]
        mean_residual[k] = r @ mean + hd[k]
        residual_cov[k] = symmetrize(r @ cov @ r.T + bz @ sig @ bz.T)
        if pairs:
            if k:
                pair_cov[k, :, :k, :] = (r @ cross[:, : k * p]).reshape(p, k, p)
                cross[:, : k * p] = t @ cross[:, : k * p]
            cross[:, k * p : (k + 1) * p] = t @ cov @ r.T + b @ sig @ bz.T
            pair_cov[k, :, k, :] = residual_cov[k]
        # the jump: -K_k H_t D_k enters e~ (the error's own share M D_k is added when it is read out)
        mean = t @ mean
        mean[d_s:] -= filt.gain[k] @ hd[k]
        cov = symmetrize(t @ cov @ t.T + b @ sig @ b.T)
        mean_error[k] = mean[d_s:] + m_d[k]
        error_cov[k] = cov[d_s:, d_s:]
        mean_estimate[k] = rec.project @ mean[:d_s] + m_d[k] - mean_error[k]
        # xhat = P_M s - e~, so Cov(e, xhat) = Cov(e~, s) P_M^T - Cov(e~)
        error_estimate[k] = cov[d_s:, :d_s] @ rec.project.T - error_cov[k] + np.outer(mean_error[k], mean_estimate[k])
        # Cov(xhat) = P_M Cov(s) P_M^T - P_M Cov(s, e~) - Cov(e~, s) P_M^T + Cov(e~)
        spread = rec.project @ cov[:d_s, d_s:]
        estimate_cov[k] = symmetrize(rec.project @ cov[:d_s, :d_s] @ rec.project.T - spread - spread.T + error_cov[k])
    second = None
    if pairs:
        lower = pair_cov.reshape(n_updates * p, n_updates * p)
        full = np.tril(lower) + np.tril(lower, -1).T
        second = full.reshape(n_updates, p, n_updates, p) + np.einsum("ka,jb->kajb", mean_residual, mean_residual)
    return Moments(mean_error, error_cov, mean_estimate, error_estimate, mean_residual, residual_cov, second, estimate_cov)


def mean_normalized_square(inverse: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """E[v^T W v] = tr(W (C + m m^T)) for v ~ (m, C), at every update: the mean NEES (W = P^{-1}) or NIS (W = S^{-1}).

    Parameters
    ----------
    inverse : ndarray, shape (K, d, d)
    mean : ndarray, shape (K, d)
    cov : ndarray, shape (K, d, d)

    Returns
    -------
    ndarray, shape (K,)
    """
    raw = cov + mean[:, :, None] * mean[:, None, :]
    return np.einsum("kij,kji->k", inverse, raw)
