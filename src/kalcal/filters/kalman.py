"""Kalman filter steps as pure functions, batched over a leading axis of realizations.

Shapes: a state is ``(..., d)``, a covariance ``(..., d, d)``, a measurement ``(..., p)`` and a
measurement matrix ``(p, d)`` (shared) or ``(..., p, d)`` (one per realization): the caller says which
by the array it passes, and every function broadcasts over the leading axes with ``@``.

Equations (prior ``xbar, M``; posterior ``xhat, P``)::

    predict:  xbar = Phi xhat,   M = Phi P Phi^T + Q
    update:   r = z - H xbar,    S = H M H^T + V,    K = M H^T S^{-1},    xhat = xbar + K r
              P = (I - K H) M (I - K H)^T + K V K^T        (form="joseph", the default)
              P = M - K H M                                (form="standard")
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import numpy as np

from kalcal.errors import ConfigError
from kalcal.linalg import symmetrize
from kalcal.models.linear import LinearGaussianModel

UpdateForm = Literal["joseph", "standard"]
UPDATE_FORMS: tuple[str, ...] = ("joseph", "standard")


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

    Returns
    -------
    gain : ndarray, shape (..., d, p)
        K = M H^T S^{-1}, computed by a solve with S.
    posterior_cov : ndarray, shape (..., d, d)
    innovation_cov : ndarray, shape (..., p, p)
    """
    if form not in UPDATE_FORMS:
        raise ConfigError(f"form: expected one of {', '.join(UPDATE_FORMS)}, got {form!r}")
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


class GainSchedule(NamedTuple):
    """Every gain and covariance of a time-invariant model, computed before any data.

    Index k = 0..K-1 is the k-th measurement update, at sample (k + 1) * steps_per_update.
    """

    prior_cov: np.ndarray  #: M_k, (K, d, d)
    posterior_cov: np.ndarray  #: P_k, (K, d, d)
    gain: np.ndarray  #: K_k, (K, d, p)
    innovation_cov: np.ndarray  #: S_k, (K, p, p)
    phi_interval: np.ndarray  #: Phi^m, (d, d)
    q_interval: np.ndarray  #: Q_m, (d, d)


def covariance_pass(model: LinearGaussianModel, n_updates: int, form: UpdateForm = "joseph") -> GainSchedule:
    """Riccati recursion alone: M_{k} = Phi_m P_{k-1} Phi_m^T + Q_m, then the update, K times.

    P_{-1} is the prior covariance M0 at sample 0.
    """
    phi_m, q_m = interval_transition(model.phi, model.gamma, model.w, model.steps_per_update)
    d, p = model.state_dim, model.measurement_dim
    prior = np.empty((n_updates, d, d))
    posterior = np.empty((n_updates, d, d))
    gains = np.empty((n_updates, d, p))
    innovation = np.empty((n_updates, p, p))
    cov = model.m0
    for k in range(n_updates):
        cov = symmetrize(phi_m @ cov @ phi_m.T + q_m)
        prior[k] = cov
        gains[k], cov, innovation[k] = gain_and_covariance(cov, model.h, model.v, form)
        posterior[k] = cov
    return GainSchedule(prior, posterior, gains, innovation, phi_m, q_m)


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
    phi_t = schedule.phi_interval.T
    h_t = h.T
    for k in range(n_updates):
        xbar = x @ phi_t
        r = z[:, k] - xbar @ h_t
        x = xbar + r @ schedule.gain[k].T
        prior[:, k], posterior[:, k], residual[:, k] = xbar, x, r
    return FilterRun(prior, posterior, residual)
