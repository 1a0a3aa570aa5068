"""The gain schedule of a time-invariant model: the covariance-only Riccati pass, then the state recursion.

A model measured every m samples is taken over one update interval (Phi_m, Q_m of
:func:`interval_transition`, or its square-root factor :func:`interval_noise_factor`); the covariance
pass runs the reference steps of :mod:`kalcal.filters.steps` without data and keeps every M_k, P_k,
K_k and S_k, so that :func:`run_with_gains` filters a batch of measurement sequences with products alone.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from kalcal.filters.sqrt_form import cholesky_factor, gram, triangularize
from kalcal.filters.steps import (
    UpdateForm,
    check_form,
    gain_and_covariance,
    predict_covariance,
    sqrt_gain_and_factor,
    sqrt_predict,
)
from kalcal.models.linear import LinearGaussianModel


def interval_transition(phi: np.ndarray, gamma: np.ndarray, w: np.ndarray, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Transition and process-noise covariance over ``steps`` samples.

    Phi_m = Phi^m and Q_m = sum_{i=0}^{m-1} Phi^i Gamma W Gamma^T (Phi^i)^T, so that
    x_{j+m} = Phi_m x_j + (noise ~ N(0, Q_m)) exactly: Q_m is m predictions of the covariance
    (:func:`~kalcal.filters.steps.predict_covariance`) from Q_0 = 0.

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
        q_m = predict_covariance(q_m, phi, step_noise)
        phi_m = phi @ phi_m
    return phi_m, q_m


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
        cov = predict_covariance(cov, transitions[k], q_m)
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

    Every measurement must be present: the gains assume every update is made (a missing measurement
    changes the covariances after it, which :func:`kalcal.filters.steps.update` handles, one step at a
    time).
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
