"""Kalman filter steps as pure functions, batched over a leading axis of realizations.

Shapes: a state is ``(..., d)``, a covariance ``(..., d, d)``, a measurement ``(..., p)`` and a
measurement matrix ``(p, d)`` (shared) or ``(..., p, d)`` (one per realization): the caller says which
by the array it passes, and every function broadcasts over the leading axes with ``@``.

Equations (prior ``xbar, M``; posterior ``xhat, P``)::

    predict:  xbar = Phi xhat,   M = Phi P Phi^T + Q
    update:   r = z - H xbar,    S = H M H^T + V,    K = M H^T S^{-1},    xhat = xbar + K r
              P = (I - K H) M (I - K H)^T + K V K^T        (form="joseph", the default)
              P = M - K H M                                (form="standard")

Square-root form (form="sqrt"): the filter carries a lower-triangular factor L with P = L L^T and never
forms P to factor it again. With tria(A) the lower-triangular T, diagonal >= 0, such that T T^T = A A^T
(from a QR decomposition of A^T)::

    predict:  L_M = tria([Phi L, G])                                  with G G^T = Q
    update:   tria([[V^{1/2}, H L_M], [0, L_M]]) = [[S^{1/2}, 0], [Kbar, L_P]],   K = Kbar S^{-1/2}

The update's post-array follows from the pre-array by an orthogonal transformation, so both have the
same Gram matrix: S^{1/2} S^{T/2} = V + H M H^T = S, Kbar = M H^T S^{-T/2} and
L_P L_P^T = M - Kbar Kbar^T = M - M H^T S^{-1} H M = P.
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import numpy as np

from kalcal.errors import ConfigError
from kalcal.linalg import symmetrize
from kalcal.models.linear import LinearGaussianModel

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


def interval_transition(phi: np.ndarray, gamma: np.ndarray, w: np.ndarray, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Transition and process-noise covariance over ``steps`` samples.

    Phi_m = Phi^m and Q_m = sum_{i=0}^{m-1} Phi^i Gamma W Gamma^T (Phi^i)^T, so that
    x_{j+m} = Phi_m x_j + (noise ~ N(0, Q_m)) exactly.

    Parameters
    ----------
    phi : ndarray, shape (d, d)
    gamma : ndarray, shape (d, q)
    w : ndarray, shape (q, q)
    steps : int, m >= 0

    Returns
    -------
    phi_m : ndarray, shape (d, d)
    q_m : ndarray, shape (d, d), symmetric
    """
    d = phi.shape[0]
    phi_m = np.eye(d)
    q_m = np.zeros((d, d))
    step_noise = gamma @ w @ gamma.T
    for _ in range(int(steps)):
        q_m = phi @ q_m @ phi.T + step_noise
        phi_m = phi @ phi_m
    return phi_m, symmetrize(q_m)


def predict(x: np.ndarray, cov: np.ndarray, phi: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Propagate a state estimate and its covariance: xbar = Phi x, M = Phi P Phi^T + Q.

    Parameters
    ----------
    x : ndarray, shape (..., d)
    cov : ndarray, shape (..., d, d)
    phi, q : ndarray, shape (d, d) or (..., d, d)
    """
    return _matvec(phi, x), symmetrize(phi @ cov @ np.swapaxes(phi, -1, -2) + q)


class UpdateResult(NamedTuple):
    """One measurement update. Shapes follow the inputs' leading axes."""

    x: np.ndarray  #: posterior state, (..., d)
    cov: np.ndarray  #: posterior covariance P, (..., d, d)
    residual: np.ndarray  #: innovation r = z - H xbar, (..., p)
    innovation_cov: np.ndarray  #: S = H M H^T + V, (..., p, p)
    gain: np.ndarray  #: K, (..., d, p)


def gain_and_covariance(
    cov: np.ndarray, h: np.ndarray, v: np.ndarray, form: UpdateForm = "joseph"
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The covariance half of an update, which needs no measurement.

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
        K = M H^T S^{-1}, computed by a solve with S.
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
    # K^T = S^{-1} H M, because S and M are symmetric.
    gain = np.swapaxes(np.linalg.solve(s, hm), -1, -2)
    if form == "joseph":
        i_kh = np.eye(cov.shape[-1]) - gain @ h
        posterior = i_kh @ cov @ np.swapaxes(i_kh, -1, -2) + gain @ v @ np.swapaxes(gain, -1, -2)
    else:
        posterior = cov - gain @ hm
    return gain, symmetrize(posterior), s


def update(
    x: np.ndarray,
    cov: np.ndarray,
    z: np.ndarray,
    h: np.ndarray,
    v: np.ndarray,
    form: UpdateForm = "joseph",
) -> UpdateResult:
    """Measurement update of a prior (xbar, M) with measurement z.

    Parameters
    ----------
    x : ndarray, shape (..., d)
    cov : ndarray, shape (..., d, d)
    z : ndarray, shape (..., p)
    h : ndarray, shape (p, d) or (..., p, d)
    v : ndarray, shape (p, p) or (..., p, p)
    form : {"joseph", "standard"}
    """
    gain, posterior, s = gain_and_covariance(cov, h, v, form)
    residual = z - _matvec(h, x)
    return UpdateResult(x + _matvec(gain, residual), posterior, residual, s, gain)


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


def _broadcast_lead(*arrays: np.ndarray) -> list[np.ndarray]:
    """Broadcast the leading (batch) axes of matrices, keeping each one's last two axes."""
    lead = np.broadcast_shapes(*(a.shape[:-2] for a in arrays))
    return [np.broadcast_to(a, lead + a.shape[-2:]) for a in arrays]


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
        G, a factor of the process noise Q = G G^T (e.g. :func:`cholesky_factor` of Q).

    Returns
    -------
    xbar : ndarray, shape (..., d)
    prior_chol : ndarray, shape (..., d, d), lower triangular
    """
    phi_l, g = _broadcast_lead(phi @ chol, np.asarray(q_chol, dtype=float))
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
    hl, chol, v_chol = _broadcast_lead(h @ chol, chol, np.asarray(v_chol, dtype=float))
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
    residual: np.ndarray  #: innovation r = z - H xbar, (..., p)
    innovation_chol: np.ndarray  #: S^{1/2}, lower-triangular factor of S, (..., p, p)
    gain: np.ndarray  #: K, (..., d, p)


def sqrt_update(
    x: np.ndarray, chol: np.ndarray, z: np.ndarray, h: np.ndarray, v_chol: np.ndarray
) -> SqrtUpdateResult:
    """Square-root measurement update of a prior (xbar, L_M) with measurement z.

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
    gain, posterior, s_chol = sqrt_gain_and_factor(chol, h, v_chol)
    residual = z - _matvec(h, x)
    return SqrtUpdateResult(x + _matvec(gain, residual), posterior, residual, s_chol, gain)


def gram(chol: np.ndarray) -> np.ndarray:
    """L L^T over the last two axes, symmetrized: the covariance a square-root factor stands for."""
    return symmetrize(chol @ np.swapaxes(chol, -1, -2))


def interval_noise_factor(phi: np.ndarray, gamma: np.ndarray, w: np.ndarray, steps: int) -> np.ndarray:
    """G_m, lower triangular, with G_m G_m^T = Q_m of :func:`interval_transition`, in square-root form.

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


class GainSchedule(NamedTuple):
    """Every gain and covariance of a time-invariant model, computed before any data.

    Index k = 0..K-1 is the k-th measurement update, at sample (k + 1) * steps_per_update.
    """

    prior_cov: np.ndarray  #: M_k, (K, d, d)
    posterior_cov: np.ndarray  #: P_k, (K, d, d)
    gain: np.ndarray  #: K_k, (K, d, p)
    innovation_cov: np.ndarray  #: S_k, (K, p, p)
    phi_interval: np.ndarray  #: Phi^m, (d, d), of the model without its time-varying part
    q_interval: np.ndarray  #: Q_m, (d, d)
    transitions: np.ndarray  #: the transition over each interval, (K, d, d) (Phi^m repeated if time-invariant)


def covariance_pass(
    model: LinearGaussianModel, n_updates: int, form: UpdateForm = "joseph", transitions: np.ndarray | None = None
) -> GainSchedule:
    """Riccati recursion alone: M_{k} = Phi_k P_{k-1} Phi_k^T + Q_m, then the update, K times.

    P_{-1} is the prior covariance M0 at sample 0. Phi_k is Phi^m for a time-invariant model, or
    ``transitions[k]`` (K, d, d) when the caller gives the transition of each interval explicitly (a
    transition that depends on a known input, such as an accelerometer scale factor's column; the
    process noise Q_m must not depend on it). ``form="sqrt"`` carries L with P = L L^T instead
    (:func:`sqrt_predict`, :func:`sqrt_gain_and_factor`, the interval noise by
    :func:`interval_noise_factor`); the schedule holds the covariances L L^T all the same.
    """
    check_form(form)
    phi_m, q_m = interval_transition(model.phi, model.gamma, model.w, model.steps_per_update)
    d, p = model.state_dim, model.measurement_dim
    if transitions is None:
        transitions = np.broadcast_to(phi_m, (n_updates, d, d))
    elif transitions.shape != (n_updates, d, d):
        raise ValueError(f"transitions: expected shape {(n_updates, d, d)}, got {transitions.shape}")
    prior = np.empty((n_updates, d, d))
    posterior = np.empty((n_updates, d, d))
    gains = np.empty((n_updates, d, p))
    innovation = np.empty((n_updates, p, p))
    if form == "sqrt":
        q_chol = interval_noise_factor(model.phi, model.gamma, model.w, model.steps_per_update)
        v_chol = cholesky_factor(model.v)
        chol = cholesky_factor(model.m0)
        for k in range(n_updates):
            _, chol = sqrt_predict(np.zeros(d), chol, transitions[k], q_chol)
            prior[k] = gram(chol)
            gains[k], chol, s_chol = sqrt_gain_and_factor(chol, model.h, v_chol)
            posterior[k], innovation[k] = gram(chol), gram(s_chol)
        return GainSchedule(prior, posterior, gains, innovation, phi_m, q_m, transitions)
    cov = model.m0
    for k in range(n_updates):
        cov = symmetrize(transitions[k] @ cov @ transitions[k].T + q_m)
        prior[k] = cov
        gains[k], cov, innovation[k] = gain_and_covariance(cov, model.h, model.v, form)
        posterior[k] = cov
    return GainSchedule(prior, posterior, gains, innovation, phi_m, q_m, transitions)


class FilterRun(NamedTuple):
    """Estimates of a batch of realizations at every update. n realizations, K updates."""

    prior: np.ndarray  #: xbar_k, (n, K, d)
    posterior: np.ndarray  #: xhat_k, (n, K, d)
    residual: np.ndarray  #: r_k = z_k - H xbar_k, (n, K, p)


def run_with_gains(schedule: GainSchedule, h: np.ndarray, z: np.ndarray, x0: np.ndarray) -> FilterRun:
    """Run the state recursion with precomputed gains over a batch of measurement sequences.

    Parameters
    ----------
    schedule : GainSchedule
        From :func:`covariance_pass`; its gains do not depend on the data.
    h : ndarray, shape (p, d)
    z : ndarray, shape (n, K, p)
        Measurements at the K updates.
    x0 : ndarray, shape (d,) or (n, d)
        Estimate at sample 0 (the prior mean).
    """
    n, n_updates, p = z.shape
    d = schedule.phi_interval.shape[0]
    prior = np.empty((n, n_updates, d))
    posterior = np.empty((n, n_updates, d))
    residual = np.empty((n, n_updates, p))
    x = np.broadcast_to(np.asarray(x0, dtype=float), (n, d))
    h_t = h.T
    for k in range(n_updates):
        xbar = x @ schedule.transitions[k].T
        r = z[:, k] - xbar @ h_t
        x = xbar + r @ schedule.gain[k].T
        prior[:, k], posterior[:, k], residual[:, k] = xbar, x, r
    return FilterRun(prior, posterior, residual)
