"""The numpy reference of every Kalman filter step: predict, the Joseph / standard / square-root updates.

Every numpy path of the package (the gain schedule, the regression filter, the calibration's loops, the
steady state) calls these functions; the compiled kernels are tested against them step for step.

Shapes: a state is ``(..., d)``, a covariance ``(..., d, d)``, a measurement ``(..., p)`` and a
measurement matrix ``(p, d)`` (shared) or ``(..., p, d)`` (one per realization): the caller says which
by the array it passes, and every function broadcasts over the leading (batch) axes with ``@``. A scalar
measurement is p = 1: z of shape ``(..., 1)`` and a row H of shape ``(..., 1, d)``.

Equations (prior ``xbar, M``; posterior ``xhat, P``)::

    predict:  xbar = Phi xhat,   M = Phi P Phi^T + Q                  (Phi = None: Phi = I, a random walk)
    update:   r = z - H xbar,    S = H M H^T + V,    K = M H^T S^{-1},    xhat = xbar + K r
              P = (I - K H) M (I - K H)^T + K V K^T        (form="joseph", the default)
              P = M - K H M                                (form="standard")

Square-root form (form="sqrt"): the filter carries a lower-triangular factor L with P = L L^T
(:mod:`kalcal.filters.sqrt_form` for tria and the factors)::

    predict:  L_M = tria([Phi L, G])                                  with G G^T = Q
    update:   tria([[V^{1/2}, H L_M], [0, L_M]]) = [[S^{1/2}, 0], [Kbar, L_P]],   K = Kbar S^{-1/2}

The update's post-array follows from the pre-array by an orthogonal transformation, so both have the
same Gram matrix: S^{1/2} S^{T/2} = V + H M H^T = S, Kbar = M H^T S^{-T/2} and
L_P L_P^T = M - Kbar Kbar^T = M - M H^T S^{-1} H M = P.

Missing measurements. A realization whose measurement has a non-finite component (NaN marks a missing
value), or whose own H holds one, is not updated: the step is a prediction only, xhat = xbar and P = M
(L_P = L_M), with K = 0 and the residual r and S (S^{1/2}) NaN. :func:`update` and :func:`sqrt_update`
do this for every caller, realization by realization, so no filter handles a missing value its own way.
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import numpy as np

from kalcal.errors import ConfigError
from kalcal.filters.sqrt_form import broadcast_lead, triangularize
from kalcal.linalg import symmetrize

UpdateForm = Literal["joseph", "standard", "sqrt"]
UPDATE_FORMS: tuple[str, ...] = ("joseph", "standard", "sqrt")
#: forms that map a covariance to a covariance (:func:`gain_and_covariance`, :func:`update`); "sqrt"
#: carries a factor instead (:func:`sqrt_predict`, :func:`sqrt_update`)
COVARIANCE_FORMS: tuple[str, ...] = ("joseph", "standard")


def check_form(form: str, name: str = "form") -> None:
    """Raise :class:`ConfigError` naming ``name`` unless ``form`` is one of :data:`UPDATE_FORMS`."""
    if form not in UPDATE_FORMS:
        raise ConfigError(f"{name}: expected one of {', '.join(UPDATE_FORMS)}, got {form!r}")


def _matvec(matrix: np.ndarray, vector: np.ndarray) -> np.ndarray:
    return (matrix @ vector[..., None])[..., 0]


def predict_covariance(cov: np.ndarray, phi: np.ndarray | None, q: np.ndarray) -> np.ndarray:
    """The covariance half of a prediction: M = Phi P Phi^T + Q, symmetrized.

    Parameters
    ----------
    cov : ndarray, shape (..., d, d)
        Posterior covariance P.
    phi : ndarray, shape (d, d) or (..., d, d), or None
        Transition; None is the identity (a random walk), which skips the two products.
    q : ndarray, shape (d, d) or (..., d, d)
        Process-noise covariance over the step.

    Returns
    -------
    ndarray, shape (..., d, d)
    """
    if phi is None:
        return symmetrize(cov + q)
    return symmetrize(phi @ cov @ np.swapaxes(phi, -1, -2) + q)


def predict(
    x: np.ndarray, cov: np.ndarray, phi: np.ndarray | None, q: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Propagate a state estimate and its covariance: xbar = Phi x, M = Phi P Phi^T + Q.

    Parameters
    ----------
    x : ndarray, shape (..., d)
    cov : ndarray, shape (..., d, d)
    phi : ndarray, shape (d, d) or (..., d, d), or None (the identity: xbar = x, M = P + Q)
    q : ndarray, shape (d, d) or (..., d, d)

    Returns
    -------
    xbar : ndarray, shape (..., d)
    prior_cov : ndarray, shape (..., d, d)
    """
    xbar = x if phi is None else _matvec(phi, x)
    return xbar, predict_covariance(cov, phi, q)


def measured(z: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Which realizations have a measurement: every component of z and every entry of H finite.

    Parameters
    ----------
    z : ndarray, shape (..., p)
    h : ndarray, shape (p, d) or (..., p, d)

    Returns
    -------
    ndarray of bool, shape (...) (the broadcast of z's and H's leading axes)
    """
    return np.all(np.isfinite(z), axis=-1) & np.all(np.isfinite(h), axis=(-2, -1))


class UpdateResult(NamedTuple):
    """One measurement update. Shapes follow the inputs' leading axes."""

    x: np.ndarray  #: posterior state, (..., d)
    cov: np.ndarray  #: posterior covariance P, (..., d, d)
    residual: np.ndarray  #: innovation r = z - H xbar, (..., p); NaN where the measurement is missing
    innovation_cov: np.ndarray  #: S = H M H^T + V, (..., p, p); NaN where the measurement is missing
    gain: np.ndarray  #: K, (..., d, p); 0 where the measurement is missing


def gain_and_covariance(
    cov: np.ndarray, h: np.ndarray, v: np.ndarray, form: UpdateForm = "joseph"
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The covariance half of an update, which needs no measurement.

    S = H M H^T + V, K = M H^T S^{-1} (by a solve with S: K^T = S^{-1} H M; a division where p = 1), and
    P = (I - K H) M (I - K H)^T + K V K^T (Joseph) or P = M - K H M (standard).

    Parameters
    ----------
    cov : ndarray, shape (..., d, d)
        Prior covariance M.
    h : ndarray, shape (p, d) or (..., p, d)
    v : ndarray, shape (p, p) or (..., p, p)
    form : {"joseph", "standard"}
        ("sqrt" carries a factor, not a covariance: :func:`sqrt_gain_and_factor`)

    Returns
    -------
    gain : ndarray, shape (..., d, p)
        K = M H^T S^{-1}, computed by a solve with S (a division for a scalar measurement).
    posterior_cov : ndarray, shape (..., d, d)
    innovation_cov : ndarray, shape (..., p, p)
    """
    if form == "sqrt":
        raise ConfigError(
            "form: 'sqrt' carries a factor of the covariance, not the covariance: use sqrt_predict and "
            "sqrt_update (or covariance_pass(form='sqrt'))"
        )
    if form not in COVARIANCE_FORMS:
        raise ConfigError(f"form: expected one of {', '.join(COVARIANCE_FORMS)}, got {form!r}")
    ht = np.swapaxes(h, -1, -2)
    hm = h @ cov
    s = symmetrize(hm @ ht + v)
    # K^T = S^{-1} H M, because S and M are symmetric; for a scalar measurement (p = 1) S^{-1} is a
    # division, which costs a hundredth of a batched 1 x 1 solve.
    gain = np.swapaxes(hm / s if s.shape[-1] == 1 else np.linalg.solve(s, hm), -1, -2)
    if form == "joseph":
        i_kh = np.eye(cov.shape[-1]) - gain @ h
        posterior = i_kh @ cov @ np.swapaxes(i_kh, -1, -2) + gain @ v @ np.swapaxes(gain, -1, -2)
    else:
        posterior = cov - gain @ hm
    return gain, symmetrize(posterior), s


def _fill_missing(present: np.ndarray, z: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """z and H with the missing realizations' entries set to 0, so that their update stays finite."""
    return np.where(present[..., None], z, 0.0), np.where(present[..., None, None], h, 0.0)


def update(
    x: np.ndarray,
    cov: np.ndarray,
    z: np.ndarray,
    h: np.ndarray,
    v: np.ndarray,
    form: UpdateForm = "joseph",
) -> UpdateResult:
    """Measurement update of a prior (xbar, M) with measurement z.

    A realization whose z (or own H) has a non-finite component keeps its prior: xhat = xbar, P = M,
    K = 0, r and S NaN (a missing measurement is a prediction only).

    Parameters
    ----------
    x : ndarray, shape (..., d)
    cov : ndarray, shape (..., d, d)
    z : ndarray, shape (..., p)
    h : ndarray, shape (p, d) or (..., p, d)
    v : ndarray, shape (p, p) or (..., p, p)
    form : {"joseph", "standard"}
    """
    present = measured(z, h)
    if not np.all(present):
        z_filled, h_filled = _fill_missing(present, z, h)
        full = update(x, cov, z_filled, h_filled, v, form)
        keep = present[..., None]
        return UpdateResult(
            np.where(keep, full.x, x),
            np.where(keep[..., None], full.cov, cov),
            np.where(keep, full.residual, np.nan),
            np.where(keep[..., None], full.innovation_cov, np.nan),
            np.where(keep[..., None], full.gain, 0.0),
        )
    gain, posterior, s = gain_and_covariance(cov, h, v, form)
    residual = z - _matvec(h, x)
    return UpdateResult(x + _matvec(gain, residual), posterior, residual, s, gain)


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
        G, a factor of the process noise Q = G G^T (e.g. :func:`~kalcal.filters.sqrt_form.cholesky_factor`
        of Q).

    Returns
    -------
    xbar : ndarray, shape (..., d)
    prior_chol : ndarray, shape (..., d, d), lower triangular
    """
    phi_l, g = broadcast_lead(phi @ chol, np.asarray(q_chol, dtype=float))
    return _matvec(phi, x), triangularize(np.concatenate([phi_l, g], axis=-1))


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

    A missing measurement (non-finite z or own H) keeps the prior, L_P = L_M, as in :func:`update`.

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
    present = measured(z, h)
    if not np.all(present):
        z_filled, h_filled = _fill_missing(present, z, h)
        full = sqrt_update(x, chol, z_filled, h_filled, v_chol)
        keep = present[..., None]
        return SqrtUpdateResult(
            np.where(keep, full.x, x),
            np.where(keep[..., None], full.chol, chol),
            np.where(keep, full.residual, np.nan),
            np.where(keep[..., None], full.innovation_chol, np.nan),
            np.where(keep[..., None], full.gain, 0.0),
        )
    gain, posterior, s_chol = sqrt_gain_and_factor(chol, h, v_chol)
    residual = z - _matvec(h, x)
    return SqrtUpdateResult(x + _matvec(gain, residual), posterior, residual, s_chol, gain)
