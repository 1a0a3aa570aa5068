"""The extended Kalman filter and its iterated update, batched over realizations, on the linear steps of core.steps.

Model (:class:`~kalcal.core.nonlinear.NonlinearModel`): x_k = f(x_{k-1}, u_k, dt) + w_k, z_k = h(x_k,
data_k) + v_k, w ~ N(0, Q), v ~ N(0, R). Prior (xbar, M), posterior (xhat, P)::

    predict (EKF):  xbar = f(xhat, u, dt),   F = df/dx at xhat,   M = F P F^T + Q
    update  (EKF):  H = dh/dx at xbar,   r = z - h(xbar),   S = H M H^T + R,   K = M H^T S^{-1}
                    xhat = xbar + K r,   P = (I - K H) M (I - K H)^T + K R K^T   (Joseph)

The EKF's update *is* the linear Joseph update (:func:`kalcal.core.steps.gain_and_covariance`) with the
Jacobian for H and the nonlinear innovation for r; a missing measurement (a non-finite component of z) is
a prediction only, by the rule every update shares (:func:`kalcal.core.missing.update_where_measured`).

The iterated update (Bell & Cathey 1993) is Gauss-Newton on the update's MAP problem
min_x |x - xbar|^2_{M^-1} + |z - h(x)|^2_{R^-1}: from x_0 = xbar,

    H_i = dh/dx at x_i,   K_i = M H_i^T (H_i M H_i^T + R)^{-1}
    x_{i+1} = xbar + K_i (z - h(x_i) - H_i (xbar - x_i))

stopping, realization by realization, when the step's size in prior standard deviations
sqrt((x_{i+1} - x_i)^T M^{-1} (x_{i+1} - x_i)) is at most ``step_tol`` (default 1e-10), or after
``max_iterations`` (default 20) iterations. xhat is the last iterate, P the Joseph form at H = dh/dx at
xhat (the last linearization). The residual and S it reports are the prior's, r = z - h(xbar) and
S = H_0 M H_0^T + R, those of the EKF (white with covariance S under the filter's own model).

Shapes: a batch of n realizations, states (n, d), covariances (n, d, d), z (p,) shared or (n, p); a
batch gives the answer of a loop over its realizations (tests/core/test_nonlinear_filters.py).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from kalcal.core.missing import measured, update_where_measured
from kalcal.core.nonlinear import NonlinearModel
from kalcal.core.steps import UpdateResult, gain_and_covariance, predict_covariance
from kalcal.errors import ConfigError
from kalcal.linalg import matvec

__all__ = ["IteratedUpdateResult", "ekf_predict", "ekf_update", "iekf_update", "take"]

#: The iterated update's defaults (the stopping rule of the module's docstring).
IEKF_MAX_ITERATIONS = 20
IEKF_STEP_TOL = 1e-10


def take(value: np.ndarray | None, index: np.ndarray) -> np.ndarray | None:
    """The rows ``index`` of a per-realization array (n, k); a shared one (k,) or None as it is."""
    if value is None:
        return None
    value = np.asarray(value, dtype=float)
    return value[index] if value.ndim == 2 else value


def ekf_predict(
    model: NonlinearModel, x: np.ndarray, cov: np.ndarray, u: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """xbar = f(x, u, dt) and M = F P F^T + Q with F = df/dx at x.

    Parameters
    ----------
    model : NonlinearModel
    x : ndarray, shape (n, d)
    cov : ndarray, shape (n, d, d)
    u : ndarray, shape (m,) or (n, m), or None where the model takes no input

    Returns
    -------
    xbar : ndarray, shape (n, d)
    prior_cov : ndarray, shape (n, d, d), symmetric
    """
    jac = model.transition_jacobian(x, u)
    return model.transition(x, u), predict_covariance(cov, jac, model.q)


def _linearized_update(x, cov, residual, h, v) -> UpdateResult:
    """The Joseph update with the innovation given (r = z - h(xbar), not z - H xbar)."""
    gain, posterior, s = gain_and_covariance(cov, h, v, "joseph")
    return UpdateResult(x + matvec(gain, residual), posterior, residual, s, gain)


def ekf_update(
    model: NonlinearModel, x: np.ndarray, cov: np.ndarray, z: np.ndarray, data: np.ndarray | None = None
) -> UpdateResult:
    """The EKF's update of a prior (xbar, M) with z: the Joseph update at H = dh/dx at xbar, r = z - h(xbar).

    Parameters
    ----------
    model : NonlinearModel
    x : ndarray, shape (n, d)
        The prior mean xbar.
    cov : ndarray, shape (n, d, d)
        The prior covariance M.
    z : ndarray, shape (p,) or (n, p)
        The measurement; a realization with a non-finite component keeps its prior (r and S NaN, K 0).
    data : ndarray, shape (k,) or (n, k), or None

    Returns
    -------
    UpdateResult
        x (n, d), cov P (n, d, d), residual r (n, p), innovation_cov S (n, p, p), gain K (n, d, p).
    """
    jac = model.measurement_jacobian(x, data)
    residual = np.asarray(z, dtype=float) - model.measure(x, data)
    return update_where_measured(_linearized_update, x, cov, residual, jac, model.r)


class IteratedUpdateResult(NamedTuple):
    """One iterated update: the fields of :class:`~kalcal.core.steps.UpdateResult` and the iterations taken."""

    x: np.ndarray  #: posterior state, the last iterate, (n, d)
    cov: np.ndarray  #: P, Joseph at the last iterate's Jacobian, (n, d, d)
    residual: np.ndarray  #: the prior's innovation z - h(xbar), (n, p); NaN where missing
    innovation_cov: np.ndarray  #: the prior's S = H_0 M H_0^T + R, (n, p, p); NaN where missing
    gain: np.ndarray  #: K at the last iterate's Jacobian, (n, d, p); 0 where missing
    iterations: np.ndarray  #: Gauss-Newton steps taken, (n,) int; 0 where missing
    converged: np.ndarray  #: the last step was within step_tol, (n,) bool; True where missing


def iekf_update(
    model: NonlinearModel,
    x: np.ndarray,
    cov: np.ndarray,
    z: np.ndarray,
    data: np.ndarray | None = None,
    *,
    max_iterations: int = IEKF_MAX_ITERATIONS,
    step_tol: float = IEKF_STEP_TOL,
) -> IteratedUpdateResult:
    """The iterated EKF's update (Bell & Cathey 1993): Gauss-Newton on the MAP of the update (module docstring).

    Parameters
    ----------
    model, x, cov, z, data
        As :func:`ekf_update`.
    max_iterations : int, >= 1
        At most this many Gauss-Newton steps per realization (1: the EKF's update).
    step_tol : float, >= 0
        A realization stops once its step, in prior standard deviations sqrt(dx^T M^{-1} dx), is at most this.

    Returns
    -------
    IteratedUpdateResult
    """
    if isinstance(max_iterations, bool) or int(max_iterations) != max_iterations or max_iterations < 1:
        raise ConfigError(f"max_iterations: expected a positive integer, got {max_iterations!r}")
    if not (np.isfinite(step_tol) and step_tol >= 0):
        raise ConfigError(f"step_tol: expected a non-negative number, got {step_tol!r}")
    n, d = x.shape
    z = np.broadcast_to(np.asarray(z, dtype=float), (n, model.measurement_dim))
    jac0 = model.measurement_jacobian(x, data)
    residual0 = z - model.measure(x, data)
    present = measured(residual0, jac0)
    p = model.measurement_dim
    out_x, out_cov = x.copy(), np.array(cov, dtype=float, copy=True)
    out_r = np.full((n, p), np.nan)
    out_s = np.full((n, p, p), np.nan)
    out_k = np.zeros((n, d, p))
    iterations = np.zeros(n, dtype=int)
    converged = np.ones(n, dtype=bool)
    rows = np.flatnonzero(present)
    if rows.size:
        xbar, prior = x[rows], cov[rows]
        zz, dd = z[rows], take(data, rows)
        # M's Cholesky factor, once: the step's size |L^{-1} dx| is its Mahalanobis norm under M
        chol = np.linalg.cholesky(prior)
        xi = xbar.copy()
        active = np.ones(rows.size, dtype=bool)
        steps = np.zeros(rows.size, dtype=int)
        for _ in range(int(max_iterations)):
            idx = np.flatnonzero(active)
            if idx.size == 0:
                break
            sub_data = take(dd, idx)
            jac = model.measurement_jacobian(xi[idx], sub_data)
            gain, _, _ = gain_and_covariance(prior[idx], jac, model.r, "joseph")
            innovation = zz[idx] - model.measure(xi[idx], sub_data) - matvec(jac, xbar[idx] - xi[idx])
            new = xbar[idx] + matvec(gain, innovation)
            step = np.linalg.solve(chol[idx], (new - xi[idx])[..., None])[..., 0]
            xi[idx] = new
            steps[idx] += 1
            active[idx] = np.sqrt(np.sum(step * step, axis=-1)) > step_tol
        jac = model.measurement_jacobian(xi, dd)
        gain, posterior, _ = gain_and_covariance(prior, jac, model.r, "joseph")
        _, _, s0 = gain_and_covariance(prior, jac0[rows], model.r, "joseph")
        out_x[rows], out_cov[rows], out_k[rows] = xi, posterior, gain
        out_r[rows], out_s[rows] = residual0[rows], s0
        iterations[rows], converged[rows] = steps, ~active
    return IteratedUpdateResult(out_x, out_cov, out_r, out_s, out_k, iterations, converged)
