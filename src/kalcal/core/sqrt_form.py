"""The square-root form: tria, factors of given covariances, L L^T, and the square-root predict and update.

The square-root steps carry a lower-triangular factor L with P = L L^T and never form P to factor it
again; they are the square-root counterparts of :func:`kalcal.core.steps.predict` and
:func:`~kalcal.core.steps.update` (form="sqrt" of the covariance pass,
:func:`~kalcal.core.steps.covariance_pass`). With tria(A) the lower-triangular T, diagonal >= 0,
such that T T^T = A A^T (from a QR decomposition of A^T), every step is one tria of a pre-array::

    predict:  L_M = tria([Phi L, G])                                  with G G^T = Q
    update:   tria([[V^{1/2}, H L_M], [0, L_M]]) = [[S^{1/2}, 0], [Kbar, L_P]],   K = Kbar S^{-1/2}

The update's post-array follows from the pre-array by an orthogonal transformation, so both have the
same Gram matrix: S^{1/2} S^{T/2} = V + H M H^T = S, Kbar = M H^T S^{-T/2} and
L_P L_P^T = M - Kbar Kbar^T = M - M H^T S^{-1} H M = P.

A missing measurement keeps the prior factor, L_P = L_M, by the same wrapper as
:func:`kalcal.core.steps.update` (:func:`kalcal.core.missing.update_where_measured`). Shapes as in
:mod:`kalcal.core.steps`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from kalcal.core.missing import update_where_measured
from kalcal.linalg import matvec, symmetrize


def triangularize(a: np.ndarray) -> np.ndarray:
    """tria(A): the lower-triangular T with T T^T = A A^T and a non-negative diagonal.

    From the QR decomposition A^T = Q R: A A^T = R^T R, so T = R^T with the signs of R's rows flipped
    where its diagonal is negative. Unique where A A^T is positive definite (its Cholesky factor).

    Parameters
    ----------
    a : ndarray, shape (..., d, n)
        Any n >= 0; fewer columns than rows are padded with zeros.

    Returns
    -------
    ndarray, shape (..., d, d)
    """
    a = np.asarray(a, dtype=float)
    d, n = a.shape[-2:]
    if n < d:
        a = np.concatenate([a, np.zeros(a.shape[:-1] + (d - n,))], axis=-1)
    r = np.linalg.qr(np.swapaxes(a, -1, -2), mode="r")
    sign = np.where(np.diagonal(r, axis1=-2, axis2=-1) < 0, -1.0, 1.0)
    return np.swapaxes(r * sign[..., :, None], -1, -2)


def cholesky_factor(cov: np.ndarray) -> np.ndarray:
    """A lower-triangular L with L L^T = cov, for the given covariances (M0, Q, V) of the square-root form.

    The Cholesky factor where ``cov`` is positive definite; otherwise (a singular Q, such as a state that
    receives no process noise) from the eigendecomposition, clipped at zero and triangularized. Never
    applied to the filter's own posterior: the square-root form carries its factor from step to step.

    Parameters
    ----------
    cov : ndarray, shape (..., d, d), symmetric positive semi-definite

    Returns
    -------
    ndarray, shape (..., d, d)
    """
    cov = symmetrize(np.asarray(cov, dtype=float))
    try:
        return np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        values, vectors = np.linalg.eigh(cov)
        return triangularize(vectors * np.sqrt(np.clip(values, 0.0, None))[..., None, :])


def gram(chol: np.ndarray) -> np.ndarray:
    """L L^T over the last two axes, symmetrized: the covariance a square-root factor stands for.

    Parameters
    ----------
    chol : ndarray, shape (..., d, r)

    Returns
    -------
    ndarray, shape (..., d, d)
    """
    return symmetrize(chol @ np.swapaxes(chol, -1, -2))


def broadcast_lead(*arrays: np.ndarray) -> list[np.ndarray]:
    """Broadcast the leading (batch) axes of matrices, keeping each one's last two axes."""
    lead = np.broadcast_shapes(*(a.shape[:-2] for a in arrays))
    return [np.broadcast_to(a, lead + a.shape[-2:]) for a in arrays]


def interval_noise_factor(phi: np.ndarray, gamma: np.ndarray, w: np.ndarray, steps: int) -> np.ndarray:
    """G_m, lower triangular, with G_m G_m^T = Q_m of :func:`kalcal.core.steps.interval_transition`, in square-root form.

    G_{i+1} = tria([Phi G_i, Gamma W^{1/2}]), G_0 = 0: the sum of the samples' noise pushed through the
    transition, without forming Q_m.

    Returns
    -------
    ndarray, shape (d, d)
    """
    d = phi.shape[0]
    step = gamma @ cholesky_factor(w)
    factor = np.zeros((d, d))
    for _ in range(int(steps)):
        factor = triangularize(np.concatenate([phi @ factor, step], axis=-1))
    return factor


def sqrt_predict(
    x: np.ndarray, chol: np.ndarray, phi: np.ndarray, q_chol: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Square-root prediction: xbar = Phi x and L_M = tria([Phi L, G]), so L_M L_M^T = Phi P Phi^T + G G^T.

    Parameters
    ----------
    x : ndarray, shape (..., d)
    chol : ndarray, shape (..., d, d)
        L, a factor of the posterior covariance P = L L^T.
    phi : ndarray, shape (d, d) or (..., d, d)
    q_chol : ndarray, shape (d, r) or (..., d, r)
        G, a factor of the process noise Q = G G^T (e.g. :func:`~kalcal.core.sqrt_form.cholesky_factor`
        of Q).

    Returns
    -------
    xbar : ndarray, shape (..., d)
    prior_chol : ndarray, shape (..., d, d), lower triangular
    """
    phi_l, g = broadcast_lead(phi @ chol, np.asarray(q_chol, dtype=float))
    return matvec(phi, x), triangularize(np.concatenate([phi_l, g], axis=-1))


def sqrt_gain_and_factor(
    chol: np.ndarray, h: np.ndarray, v_chol: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The covariance half of a square-root update, by the array (QR) algorithm.

    tria([[V^{1/2}, H L_M], [0, L_M]]) = [[S^{1/2}, 0], [Kbar, L_P]] and K = Kbar S^{-1/2} (a solve).

    Parameters
    ----------
    chol : ndarray, shape (..., d, d)
        L_M, a factor of the prior covariance M = L_M L_M^T.
    h : ndarray, shape (p, d) or (..., p, d)
    v_chol : ndarray, shape (p, p) or (..., p, p)
        V^{1/2}, a factor of the measurement noise V (e.g. its Cholesky factor).

    Returns
    -------
    gain : ndarray, shape (..., d, p)
    posterior_chol : ndarray, shape (..., d, d)
        L_P, lower triangular with P = L_P L_P^T.
    innovation_chol : ndarray, shape (..., p, p)
        S^{1/2}, lower triangular with S = H M H^T + V = S^{1/2} S^{T/2}.
    """
    hl, chol, v_chol = broadcast_lead(h @ chol, chol, np.asarray(v_chol, dtype=float))
    p, d = hl.shape[-2:]
    pre = np.zeros(hl.shape[:-2] + (p + d, p + d))
    pre[..., :p, :p] = v_chol
    pre[..., :p, p:] = hl
    pre[..., p:, p:] = chol
    post = triangularize(pre)
    s_chol, kbar = post[..., :p, :p], post[..., p:, :p]
    # K^T = S^{-T/2} Kbar^T
    gain = np.swapaxes(np.linalg.solve(np.swapaxes(s_chol, -1, -2), np.swapaxes(kbar, -1, -2)), -1, -2)
    return gain, post[..., p:, p:], s_chol


class SqrtUpdateResult(NamedTuple):
    """One square-root measurement update. Shapes follow the inputs' leading axes."""

    x: np.ndarray  #: posterior state, (..., d)
    chol: np.ndarray  #: L_P, lower-triangular factor of the posterior covariance, (..., d, d)
    residual: np.ndarray  #: innovation r = z - H xbar, (..., p); NaN where the measurement is missing
    innovation_chol: np.ndarray  #: S^{1/2}, lower-triangular factor of S, (..., p, p); NaN where missing
    gain: np.ndarray  #: K, (..., d, p); 0 where the measurement is missing


def sqrt_update(
    x: np.ndarray, chol: np.ndarray, z: np.ndarray, h: np.ndarray, v_chol: np.ndarray
) -> SqrtUpdateResult:
    """Square-root measurement update of a prior (xbar, L_M) with measurement z.

    A missing measurement (non-finite z or own H) keeps the prior, L_P = L_M, as in :func:`kalcal.core.steps.update`.

    Parameters
    ----------
    x : ndarray, shape (..., d)
    chol : ndarray, shape (..., d, d)
        L_M with M = L_M L_M^T.
    z : ndarray, shape (..., p)
    h : ndarray, shape (p, d) or (..., p, d)
    v_chol : ndarray, shape (p, p) or (..., p, p)
        A factor of V.
    """
    return update_where_measured(_sqrt_update_every, x, chol, z, h, v_chol)


def _sqrt_update_every(x, chol, z, h, v_chol) -> SqrtUpdateResult:
    """:func:`sqrt_update` of every realization, its z and H finite."""
    gain, posterior, s_chol = sqrt_gain_and_factor(chol, h, v_chol)
    residual = z - matvec(h, x)
    return SqrtUpdateResult(x + matvec(gain, residual), posterior, residual, s_chol, gain)
