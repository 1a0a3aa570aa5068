"""Exact sampling of the truth at the update rate.

Between two updates the truth is linear in its noise samples, so the state at the next update is
Gaussian given the state now: its noise over one interval is drawn with a covariance computed once,
instead of sample by sample. A scheme that shares a noise sample between neighbouring intervals (the
trapezoid rule uses each accelerometer sample in two steps) draws that boundary sample explicitly.
Deterministic model error (an integration scheme against an analytic truth) is computed once and added.

The truth at update k (k = 0..K-1, after k + 1 intervals)::

    y_0 = x_0 ~ N(x0_mean, F0 F0^T),   u_0 ~ N(0, 1)
    y_{k+1} = A_k y_k + L xi_k + b_in u_k + b_out u_{k+1},   xi_k ~ N(0, I_r),  u_k ~ N(0, 1)
    x_k = y_{k+1} + D_k,    z_k = H x_k + G eta_k,           eta_k ~ N(0, I_p)

A truth may have more states than the filter (reduced-order design): then ``error_map`` M (d_f, d) says
which combination of the truth's states the filter estimates, and the filter's error is M x_k - xhat_k.

Draw order for n realizations: ``(d0 + c, n)`` for x_0 and u_0, then ``(K, r + c + p, n)``, where c is 1
when a boundary sample is shared and 0 when it is not (the intervals are then independent). The
realization index is the last, contiguous axis, as the compiled engine reads it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kalcal.core.model import LinearGaussianModel
from kalcal.core.steps import interval_transition
from kalcal.linalg import psd_factor


@dataclass(frozen=True)
class UpdateRateTruth:
    """The truth at the update rate. d states, p measurements, K updates, r independent noise directions.

    The filter estimates d_f states: the truth's own (``error_map`` None, d_f = d), or M x for a truth
    with states of its own (``error_map`` M, (d_f, d)).
    """

    transitions: np.ndarray  #: A_k over interval k, (K, d, d) (time-invariant models repeat one)
    noise_factor: np.ndarray  #: L, (d, r)
    boundary_in: np.ndarray  #: b_in, weight of the shared sample that opens an interval, (d,)
    boundary_out: np.ndarray  #: b_out, weight of the shared sample that closes it, (d,)
    model_error: np.ndarray  #: D_k, deterministic error added at each update, (K, d)
    x0_mean: np.ndarray  #: (d,)
    x0_factor: np.ndarray  #: F0, (d, d0)
    h: np.ndarray  #: (p, d)
    measurement_factor: np.ndarray  #: G, (p, p)
    error_map: np.ndarray | None = None  #: M, (d_f, d): the filter's states are M x; None: M = I
    #: nu: 0 for Gaussian measurement noise G w; an integer nu > 2 for G t, each component of t an
    #: independent Student t(nu) scaled to unit variance, t_a = w_a sqrt((nu - 2) / chi2_a), chi2_a the sum of
    #: nu more squared standard normals: the same covariance G G^T, heavier tails (:func:`student_t_noise`)
    measurement_dof: int = 0

    def __post_init__(self) -> None:
        nu = self.measurement_dof
        if nu != 0 and (int(nu) != nu or nu <= 2):
            raise ValueError(f"measurement_dof: expected 0 (Gaussian) or an integer above 2, got {nu!r}")

    @property
    def measurement_draws(self) -> int:
        """Standard normals per update of the measurement noise: p (Gaussian) or p (1 + nu) (Student t)."""
        p = self.h.shape[0]
        return p * (1 + int(self.measurement_dof))

    @property
    def error_dim(self) -> int:
        """d_f, the states the filter estimates (the rows of M; d when there is no map)."""
        return self.state_dim if self.error_map is None else self.error_map.shape[0]

    @property
    def n_updates(self) -> int:
        return self.model_error.shape[0]

    @property
    def state_dim(self) -> int:
        return self.transitions.shape[-1]

    @property
    def shares_boundary(self) -> bool:
        """Whether neighbouring intervals share a noise sample."""
        return bool(np.any(self.boundary_in != 0.0) or np.any(self.boundary_out != 0.0))

    @property
    def normals_per_realization(self) -> int:
        """Standard normals one realization draws: the cost the engine is measured against."""
        c = int(self.shares_boundary)
        return self.x0_factor.shape[1] + c + self.n_updates * (self.noise_factor.shape[1] + c + self.measurement_draws)


def truth_from_model(model: LinearGaussianModel, n_updates: int, model_error: np.ndarray | None = None) -> UpdateRateTruth:
    """A linear Gaussian model sampled exactly at its update rate (independent intervals).

    A :class:`~kalcal.scenarios.model_file.truth.MappedTruthModel` brings its map to the filter's states
    (``error_map``); any other model is over the filter's own states.
    """
    phi_m, q_m = interval_transition(model.phi, model.gamma, model.w, model.steps_per_update)
    d = model.state_dim
    return UpdateRateTruth(
        transitions=np.broadcast_to(phi_m, (n_updates,) + phi_m.shape),
        noise_factor=psd_factor(q_m),
        boundary_in=np.zeros(d),
        boundary_out=np.zeros(d),
        model_error=np.zeros((n_updates, d)) if model_error is None else np.asarray(model_error, dtype=float),
        x0_mean=model.x0,
        x0_factor=psd_factor(model.m0),
        h=model.h,
        measurement_factor=np.linalg.cholesky(model.v),
        error_map=getattr(model, "map", None),  # a truth with more states than the filter carries its map
    )


def student_t_noise(draws: np.ndarray, p: int, dof: int) -> np.ndarray:
    """Unit-variance Student t(dof) noise from standard normals: ``draws`` (..., p (1 + dof)) holds the p
    numerators w_a, then dof normals per component whose squares sum to chi2_a; returns (..., p),
    t_a = w_a sqrt((dof - 2) / chi2_a) (Var t(dof) = dof / (dof - 2), so the scaling leaves variance 1).
    """
    chi2 = np.square(draws[..., p:]).reshape(*draws.shape[:-1], p, dof).sum(axis=-1)
    return draws[..., :p] * np.sqrt((dof - 2) / chi2)


def sample_exact(truth: UpdateRateTruth, rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Draw n realizations of the states and measurements at every update.

    Returns
    -------
    states : ndarray, shape (n, K, d)
        The truth's own states (before any ``error_map``).
    measurements : ndarray, shape (n, K, p)
    """
    d, r = truth.noise_factor.shape
    d0 = truth.x0_factor.shape[1]
    p = truth.h.shape[0]
    c = int(truth.shares_boundary)
    n_updates = truth.n_updates
    first = rng.standard_normal((d0 + c, n)).T
    draws = rng.standard_normal((n_updates, r + c + truth.measurement_draws, n)).transpose(0, 2, 1)
    y = truth.x0_mean + first[:, :d0] @ truth.x0_factor.T
    u = first[:, d0:]  # (n, c): the boundary sample that opens the next interval
    # Stack [L | b_out] so that one product adds the independent noise and the closing boundary sample.
    noise_t = np.vstack([truth.noise_factor.T, truth.boundary_out[None, :]][: 1 + c])
    boundary_in = truth.boundary_in[None, :][:c]
    measure_t = truth.measurement_factor.T
    h_t = truth.h.T
    states = np.empty((n, n_updates, d))
    measurements = np.empty((n, n_updates, p))
    for k in range(n_updates):
        step = draws[k]
        y = y @ truth.transitions[k].T + step[:, : r + c] @ noise_t + u @ boundary_in
        u = step[:, r : r + c]
        x = y + truth.model_error[k]
        states[:, k] = x
        noise = step[:, r + c :]
        if truth.measurement_dof:
            noise = student_t_noise(noise, p, int(truth.measurement_dof))
        measurements[:, k] = x @ h_t + noise @ measure_t
    return states, measurements
