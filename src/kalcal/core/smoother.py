"""The Rauch-Tung-Striebel (RTS) smoother, a pure function over a filter's run, batched.

The filter's K updates give, for k = 0..K-1, the prior (xbar_k, M_k) before update k, the posterior
(xhat_k, P_k) after it, and Phi_k, the transition from update k-1 (or the prior) to update k. The
smoother runs backwards from x_s,K-1 = xhat_K-1, P_s,K-1 = P_K-1::

    C_k    = P_k Phi_{k+1}^T M_{k+1}^{-1}                  (by a solve with M_{k+1}, never an inverse)
    x_s,k  = xhat_k + C_k (x_s,k+1 - xbar_k+1)
    P_s,k  = P_k + C_k (P_s,k+1 - M_k+1) C_k^T

x_s,k and P_s,k are the mean and covariance of x_k given all K measurements (for a filter whose model is
right). Shapes: states (..., K, d), covariances (..., K, d, d); covariances and transitions may be shared
by every realization (K, d, d) while the states carry a batch axis (n, K, d), as in a fixed-gain run.
The transitions are always one per update: a time-invariant model passes ``np.broadcast_to(phi, (K, d, d))``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from kalcal.errors import ConfigError
from kalcal.linalg import symmetrize


class SmoothedRun(NamedTuple):
    """The smoothed estimates at the K updates; leading axes follow the inputs'."""

    state: np.ndarray  #: x_s,k, (..., K, d)
    cov: np.ndarray  #: P_s,k, (..., K, d, d)
    gain: np.ndarray  #: C_k, (..., K - 1, d, d)


def rts_smooth(
    posterior_state: np.ndarray,
    posterior_cov: np.ndarray,
    prior_state: np.ndarray,
    prior_cov: np.ndarray,
    transition: np.ndarray,
) -> SmoothedRun:
    """Smooth a filter's run backwards over its K updates.

    Parameters
    ----------
    posterior_state : ndarray, shape (..., K, d)
        xhat_k.
    posterior_cov : ndarray, shape (..., K, d, d)
        P_k.
    prior_state : ndarray, shape (..., K, d)
        xbar_k = Phi_k xhat_{k-1} (index 0, the prediction from the prior, is not used).
    prior_cov : ndarray, shape (..., K, d, d)
        M_k, positive definite for k >= 1.
    transition : ndarray, shape (..., K, d, d)
        Phi_k from update k-1 to update k (index 0 is not used).

    Returns
    -------
    SmoothedRun
        x_s,k (..., K, d), P_s,k (..., K, d, d) and the smoother gains C_k (..., K - 1, d, d).

    Raises
    ------
    ConfigError
        The arrays do not agree on K and d.
    """
    xhat = np.asarray(posterior_state, dtype=float)
    p = np.asarray(posterior_cov, dtype=float)
    xbar = np.asarray(prior_state, dtype=float)
    m = np.asarray(prior_cov, dtype=float)
    phi = np.asarray(transition, dtype=float)
    if xhat.ndim < 2:
        raise ConfigError(f"posterior_state: expected shape (..., K, d), got {xhat.shape}")
    n_updates, d = xhat.shape[-2:]
    for name, array, tail in (
        ("posterior_cov", p, (n_updates, d, d)),
        ("prior_state", xbar, (n_updates, d)),
        ("prior_cov", m, (n_updates, d, d)),
        ("transition", phi, (n_updates, d, d)),
    ):
        if array.shape[-len(tail):] != tail:
            raise ConfigError(f"{name}: expected shape (..., {', '.join(map(str, tail))}), got {array.shape}")
    lead_x = np.broadcast_shapes(xhat.shape[:-2], xbar.shape[:-2], p.shape[:-3], m.shape[:-3], phi.shape[:-3])
    lead_p = np.broadcast_shapes(p.shape[:-3], m.shape[:-3], phi.shape[:-3])
    state = np.empty(lead_x + (n_updates, d))
    cov = np.empty(lead_p + (n_updates, d, d))
    gains = np.empty(lead_p + (max(n_updates - 1, 0), d, d))
    state[..., -1, :] = xhat[..., -1, :]
    cov[..., -1, :, :] = p[..., -1, :, :]
    for k in range(n_updates - 2, -1, -1):
        p_k, m_next, phi_next = p[..., k, :, :], m[..., k + 1, :, :], phi[..., k + 1, :, :]
        # C_k^T = M_{k+1}^{-1} Phi_{k+1} P_k, since M and P are symmetric.
        c = np.swapaxes(np.linalg.solve(m_next, phi_next @ p_k), -1, -2)
        gains[..., k, :, :] = c
        state[..., k, :] = xhat[..., k, :] + (c @ (state[..., k + 1, :] - xbar[..., k + 1, :])[..., None])[..., 0]
        cov[..., k, :, :] = symmetrize(p_k + c @ (cov[..., k + 1, :, :] - m_next) @ np.swapaxes(c, -1, -2))
    return SmoothedRun(state, cov, gains)
