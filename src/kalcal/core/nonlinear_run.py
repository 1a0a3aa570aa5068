"""One pass of a nonlinear filter (EKF, iterated EKF, UKF) over K updates, for a batch of realizations.

Each update k = 0..K-1 is one predict (f over dt, with u_k) and one update with z_k (h with data_k).
Per update the caller gets the posterior state (n, d), P (n, d, d), the innovation r (n, p) and S
(n, p, p), batch axis first: through ``on_update(k, result)`` (no per-update result kept; the measurements
z, (n, K, p), are the caller's and grow with K) and, with ``keep=True``, stacked in a :class:`NonlinearRun`
as (n, K, ...).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Literal

import numpy as np

from kalcal.core.ekf import ekf_predict, ekf_update, iekf_update
from kalcal.core.nonlinear import NonlinearModel
from kalcal.core.ukf import UnscentedSettings, ukf_predict, ukf_update
from kalcal.errors import ConfigError

__all__ = ["FILTERS", "NonlinearRun", "run_nonlinear_filter"]

FILTERS: tuple[str, ...] = ("ekf", "iekf", "ukf")


@dataclass(frozen=True)
class NonlinearRun:
    """A filter's posteriors and innovations at every update, batch axis first."""

    x: np.ndarray  #: (n, K, d)
    cov: np.ndarray  #: (n, K, d, d)
    residual: np.ndarray  #: (n, K, p); NaN where missing
    innovation_cov: np.ndarray  #: (n, K, p, p); NaN where missing


def _at(value: np.ndarray | None, k: int, name: str) -> np.ndarray | None:
    """Update k's row of inputs given shared (K, m) or per realization (n, K, m): the rank says which."""
    if value is None:
        return None
    value = np.asarray(value, dtype=float)
    if value.ndim == 2:
        return value[k]
    if value.ndim == 3:
        return value[:, k]
    raise ConfigError(f"{name}: expected shape (K, size) shared or (n, K, size) per realization, got {value.shape}")


def run_nonlinear_filter(
    model: NonlinearModel,
    z: np.ndarray,
    *,
    method: Literal["ekf", "iekf", "ukf"] = "ekf",
    u: np.ndarray | None = None,
    data: np.ndarray | None = None,
    x0: np.ndarray | None = None,
    p0: np.ndarray | None = None,
    unscented: UnscentedSettings = UnscentedSettings(),
    max_iterations: int = 20,
    step_tol: float = 1e-10,
    on_update: Callable[[int, object], None] | None = None,
    keep: bool = True,
) -> NonlinearRun | None:
    """Filter n realizations' measurements z (n, K, p) from the prior (x0, P0) (the model's by default).

    Parameters
    ----------
    model : NonlinearModel
    z : ndarray, shape (n, K, p)
        NaN marks a missing measurement (that update is a prediction only).
    method : {"ekf", "iekf", "ukf"}
    u : ndarray, shape (K, m) shared or (n, K, m), or None
    data : ndarray, shape (K, k) shared or (n, K, k), or None
    x0 : ndarray, shape (d,) or (n, d); p0 : ndarray, shape (d, d) or (n, d, d)
    unscented : UnscentedSettings
        The UKF's alpha, beta, kappa.
    max_iterations, step_tol
        The IEKF's stopping rule (:func:`kalcal.core.ekf.iekf_update`).
    on_update : callable(k, result) or None
        Called after each update with its result (an UpdateResult, or IteratedUpdateResult for the IEKF).
    keep : bool
        Stack every update's result in the returned :class:`NonlinearRun` (n K (d + d^2 + p + p^2) floats).

    Returns
    -------
    NonlinearRun, or None where ``keep`` is False
    """
    if method not in FILTERS:
        raise ConfigError(f"method: expected one of {', '.join(FILTERS)}, got {method!r}")
    z = np.asarray(z, dtype=float)
    d, p = model.state_dim, model.measurement_dim
    if z.ndim != 3 or z.shape[2] != p:
        raise ConfigError(f"z: expected shape (n, K, {p}), got {z.shape}")
    n, n_updates = z.shape[:2]
    x = np.broadcast_to(model.x0 if x0 is None else np.asarray(x0, dtype=float), (n, d)).copy()
    cov = np.broadcast_to(model.p0 if p0 is None else np.asarray(p0, dtype=float), (n, d, d)).copy()
    if keep:
        run = NonlinearRun(np.empty((n, n_updates, d)), np.empty((n, n_updates, d, d)),
                        np.empty((n, n_updates, p)), np.empty((n, n_updates, p, p)))
    for k in range(n_updates):
        u_k, data_k = _at(u, k, "u"), _at(data, k, "data")
        if method == "ukf":
            x, cov = ukf_predict(model, x, cov, u_k, unscented)
            result = ukf_update(model, x, cov, z[:, k], data_k, unscented)
        else:
            x, cov = ekf_predict(model, x, cov, u_k)
            if method == "ekf":
                result = ekf_update(model, x, cov, z[:, k], data_k)
            else:
                result = iekf_update(model, x, cov, z[:, k], data_k, max_iterations=max_iterations, step_tol=step_tol)
        x, cov = result.x, result.cov
        if keep:
            run.x[:, k], run.cov[:, k] = x, cov
            run.residual[:, k], run.innovation_cov[:, k] = result.residual, result.innovation_cov
        if on_update is not None:
            on_update(k, result)
    return run if keep else None
