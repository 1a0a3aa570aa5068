"""The linear Gaussian state-space model, as an immutable description.

The model runs at a fast *sample* rate and is observed every ``steps_per_update`` samples::

    x_{j+1} = Phi x_j + Gamma w_j,          w_j ~ N(0, W)        (every sample j)
    z_k     = H x_{k m} + v_k,               v_k ~ N(0, V)        (every m = steps_per_update samples)
    x_0 ~ N(x0, M0)

The first measurement is taken after ``steps_per_update`` samples (at sample m, not at sample 0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kalcal.models.settings import SettingError, require_shape, show


def _as_matrix(name: str, value, shape: tuple[int, int] | None = None) -> np.ndarray:
    array = np.array(value, dtype=float)
    if array.ndim != 2:
        raise SettingError(name, "a matrix", f"an array of shape {array.shape}")
    if shape is not None:
        require_shape(name, array, shape)
    if not np.all(np.isfinite(array)):
        raise SettingError(name, "finite numbers", show(array))
    array.setflags(write=False)
    return array


def check_covariance(name: str, matrix: np.ndarray, *, rtol: float = 1e-9) -> None:
    """Raise a :class:`~kalcal.models.settings.SettingError` unless ``matrix`` is symmetric positive semi-definite.

    Parameters
    ----------
    name : str
        The setting's name, quoted in the error.
    matrix : ndarray, shape (d, d)
    rtol : float
        Tolerance relative to the largest absolute entry, for symmetry and for negative eigenvalues.
    """
    scale = max(float(np.max(np.abs(matrix), initial=0.0)), np.finfo(float).tiny)
    if not np.allclose(matrix, matrix.T, rtol=0.0, atol=rtol * scale):
        raise SettingError(name, "a symmetric covariance", show(matrix))
    smallest = float(np.linalg.eigvalsh(matrix).min(initial=0.0))
    if smallest < -rtol * scale:
        raise SettingError(name, "a positive semi-definite covariance", f"{show(matrix)} (eigenvalue {smallest:.3g})")


@dataclass(frozen=True)
class LinearGaussianModel:
    """A time-invariant linear Gaussian model sampled at a fast rate and measured at a slower one.

    Attributes
    ----------
    phi : ndarray, shape (d, d)
        State transition over one sample.
    gamma : ndarray, shape (d, q)
        Process-noise input matrix.
    h : ndarray, shape (p, d)
        Measurement matrix.
    w : ndarray, shape (q, q)
        Process-noise covariance per sample.
    v : ndarray, shape (p, p)
        Measurement-noise covariance.
    x0 : ndarray, shape (d,)
        Prior mean of the state at sample 0.
    m0 : ndarray, shape (d, d)
        Prior covariance of the state at sample 0.
    steps_per_update : int
        Samples between two measurement updates (m >= 1).
    sample_period : float
        Seconds per sample, used only to put times on results.
    """

    phi: np.ndarray
    gamma: np.ndarray
    h: np.ndarray
    w: np.ndarray
    v: np.ndarray
    x0: np.ndarray
    m0: np.ndarray
    steps_per_update: int = 1
    sample_period: float = 1.0

    def __post_init__(self) -> None:
        phi = _as_matrix("phi", self.phi)
        d = phi.shape[0]
        if phi.shape != (d, d):
            raise SettingError("phi", "a square matrix", f"shape {phi.shape}")
        gamma = _as_matrix("gamma", self.gamma)
        if gamma.shape[0] != d:
            raise SettingError("gamma", f"{d} rows to match phi", f"shape {gamma.shape}")
        q = gamma.shape[1]
        h = _as_matrix("h", self.h)
        if h.shape[1] != d:
            raise SettingError("h", f"{d} columns to match phi", f"shape {h.shape}")
        p = h.shape[0]
        w = _as_matrix("w", self.w, (q, q))
        v = _as_matrix("v", self.v, (p, p))
        m0 = _as_matrix("m0", self.m0, (d, d))
        x0 = np.array(self.x0, dtype=float).reshape(-1)
        if x0.shape != (d,):
            raise SettingError("x0", f"{d} entries to match phi", str(x0.size))
        x0.setflags(write=False)
        for name, cov in (("w", w), ("v", v), ("m0", m0)):
            check_covariance(name, cov)
        if np.linalg.eigvalsh(v).min() <= 0:
            raise SettingError("v", "a positive definite measurement-noise covariance", show(v))
        steps = int(self.steps_per_update)
        if steps != self.steps_per_update or steps < 1:
            raise SettingError("steps_per_update", "a positive integer", show(self.steps_per_update))
        if not (np.isfinite(self.sample_period) and self.sample_period > 0):
            raise SettingError("sample_period", "a positive number", show(self.sample_period))
        for name, value in (("phi", phi), ("gamma", gamma), ("h", h), ("w", w), ("v", v), ("x0", x0), ("m0", m0)):
            object.__setattr__(self, name, value)
        object.__setattr__(self, "steps_per_update", steps)
        object.__setattr__(self, "sample_period", float(self.sample_period))

    @property
    def state_dim(self) -> int:
        """d, the number of states."""
        return self.phi.shape[0]

    @property
    def measurement_dim(self) -> int:
        """p, the number of measured components."""
        return self.h.shape[0]

    @property
    def update_period(self) -> float:
        """Seconds between two measurement updates."""
        return self.steps_per_update * self.sample_period
