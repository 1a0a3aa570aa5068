"""Nonlinear models several tests share: the range-bearing example, a linear model written as code, a simulator."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np

from kalcal.core.model import LinearGaussianModel
from kalcal.core.nonlinear import NonlinearModel, load_nonlinear_model
from kalcal.linalg import psd_factor

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "range_bearing.py"


def range_bearing() -> NonlinearModel:
    """The example's MODEL, read through the loader."""
    return load_nonlinear_model(EXAMPLE).filter


def range_bearing_jacobian(x: np.ndarray, beacon: np.ndarray) -> np.ndarray:
    """dh/dx of range and bearing, by hand (the oracle of the derived Jacobians): x (n, 4) -> (n, 2, 4)."""
    dx, dy = x[:, 0] - beacon[..., 0], x[:, 1] - beacon[..., 1]
    r2 = dx * dx + dy * dy
    rng = np.sqrt(r2)
    jac = np.zeros((x.shape[0], 2, 4))
    jac[:, 0, 0], jac[:, 0, 1] = dx / rng, dy / rng
    jac[:, 1, 0], jac[:, 1, 1] = -dy / r2, dx / r2
    return jac


def linear_pair() -> tuple[LinearGaussianModel, NonlinearModel]:
    """A constant-velocity model with a position-and-velocity-sum measurement, linear and as code."""
    phi = np.array([[1.0, 0.5, 0.0], [0.0, 1.0, 0.5], [0.0, 0.0, 0.9]])
    gamma = np.array([[0.1, 0.0], [0.5, 0.0], [0.0, 1.0]])
    w = np.diag([0.2, 0.05])
    hmat = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 1.0]])
    v = np.array([[1.0, 0.2], [0.2, 0.5]])
    x0 = np.array([1.0, -2.0, 0.5])
    m0 = np.array([[2.0, 0.3, 0.0], [0.3, 1.0, 0.1], [0.0, 0.1, 0.4]])
    linear = LinearGaussianModel(phi=phi, gamma=gamma, h=hmat, w=w, v=v, x0=x0, m0=m0, steps_per_update=1, sample_period=0.5)
    code = NonlinearModel(
        f=lambda x, u, dt: x @ phi.T,
        h=lambda x, data: x @ hmat.T,
        q=gamma @ w @ gamma.T,
        r=v,
        x0=x0,
        p0=m0,
        dt=0.5,
        state_names=("a", "b", "c"),
        state_units=("m", "m/s", "m/s^2"),
        measurement_names=("a", "b+c"),
        measurement_units=("m", "m/s"),
    )
    return linear, code


def simulate(model: NonlinearModel, n: int, n_updates: int, rng: np.random.Generator, data=None) -> tuple[np.ndarray, np.ndarray]:
    """Truth states (n, K, d) and measurements (n, K, p) drawn from the model itself."""
    d, p = model.state_dim, model.measurement_dim
    x = model.x0 + rng.standard_normal((n, d)) @ np.linalg.cholesky(model.p0).T
    q_factor, r_chol = psd_factor(model.q), np.linalg.cholesky(model.r)
    states, meas = np.empty((n, n_updates, d)), np.empty((n, n_updates, p))
    for k in range(n_updates):
        x = model.transition(x) + rng.standard_normal((n, q_factor.shape[1])) @ q_factor.T
        states[:, k] = x
        meas[:, k] = model.measure(x, data) + rng.standard_normal((n, p)) @ r_chol.T
    return states, meas
