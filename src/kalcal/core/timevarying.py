"""A linear Gaussian model whose measurement rows, noise and inputs change from step to step.

A model whose measurement rows are taken from data (regressors), driven by known inputs, or given a
std per measurement is not a :class:`~kalcal.core.model.LinearGaussianModel` (one H, one V for every
update) but this container, one row per model step j = 0..J-1 of ``sample_period``::

    x_{j+1} = Phi x_j + B u_j + Gamma w_j,      w_j ~ N(0, W)          (j = 0..J-2)
    z_j     = H_j x_j + v_j,                    v_j ~ N(0, V_j)        (the components measured at row j)
    x_0 ~ N(x0, M0),  the states in ``diffuse`` without any prior information

The prior is that of the state at row 0, before row 0's measurement (the convention of statsmodels'
state-space models: its a_1, P_1 are the state at the first observation). A component i of row j is
measured where z_j[i] and every entry of H_j[i] are finite (:func:`measured_components`); the rest of the
row still updates. u_j drives the step from row j to row j + 1 (the last row's input is not used).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kalcal.core.model import _as_matrix, check_covariance
from kalcal.models.settings import SettingError, show, type_name

__all__ = ["TimeVaryingModel", "measured_components"]


@dataclass(frozen=True)
class TimeVaryingModel:
    """The model of a log: constant dynamics, rows, noise and inputs per step.

    Attributes
    ----------
    phi : ndarray, shape (d, d)
        Transition over one step.
    gamma : ndarray, shape (d, q)
        Process-noise input.
    w : ndarray, shape (q, q)
        Process-noise covariance per step.
    b : ndarray, shape (d, m)
        Known-input matrix, exactly this shape (m = 0: no inputs; None or [] read as that). Any other
        shape is a :class:`~kalcal.models.settings.SettingError` naming ``b``, never reshaped.
    x0 : ndarray, shape (d,)
        Prior mean at row 0 (entries of diffuse states are not used).
    m0 : ndarray, shape (d, d)
        Prior covariance at row 0; the rows and columns of diffuse states are zero.
    h : ndarray, shape (J, p, d)
        H_j, the measurement rows at each step (NaN where a data column named in h is empty: that
        component is not measured there).
    v : ndarray, shape (J, p, p)
        V_j, the measurement-noise covariance at each step, positive definite.
    u : ndarray, shape (J, m)
        The known inputs u_j, finite, exactly this shape (a SettingError naming ``u`` otherwise).
    diffuse : ndarray of bool, shape (d,)
        The states with no prior information (a diffuse prior, the limit of an infinite variance).
    sample_period : float
        Seconds per step.
    times : ndarray, shape (J,)
        Each row's time (s).
    """

    phi: np.ndarray
    gamma: np.ndarray
    w: np.ndarray
    b: np.ndarray
    x0: np.ndarray
    m0: np.ndarray
    h: np.ndarray
    v: np.ndarray
    u: np.ndarray
    diffuse: np.ndarray
    sample_period: float
    times: np.ndarray

    def __post_init__(self) -> None:
        phi = _as_matrix("phi", self.phi)
        d = phi.shape[0]
        if phi.shape != (d, d):
            raise SettingError("phi", "a square matrix", f"shape {phi.shape}")
        gamma = _as_matrix("gamma", self.gamma)
        if gamma.shape[0] != d:
            raise SettingError("gamma", f"{d} rows to match phi", f"shape {gamma.shape}")
        w = _as_matrix("w", self.w, (gamma.shape[1], gamma.shape[1]))
        # exact shapes, never a reshape: a (1, 2) b with d = 2 read as (2, 1) would drive the wrong states
        # (no inputs: None, [] or a (d, 0) matrix)
        b = _inputs("b", self.b, d)
        if b.shape[0] != d:
            raise SettingError("b", f"a matrix of shape ({d}, m), one row per state", f"shape {b.shape}")
        m0 = _as_matrix("m0", self.m0, (d, d))
        x0 = np.array(self.x0, dtype=float).reshape(-1)
        if x0.shape != (d,):
            raise SettingError("x0", f"{d} entries to match phi", str(x0.size))
        h = np.array(self.h, dtype=float)
        if h.ndim != 3 or h.shape[2] != d:
            raise SettingError("h", f"rows per step of shape (J, p, {d})", f"shape {h.shape}")
        n, p = h.shape[:2]
        v = np.array(self.v, dtype=float)
        if v.shape != (n, p, p) or not np.all(np.isfinite(v)):
            raise SettingError("v", f"finite covariances per step of shape {(n, p, p)}", f"shape {v.shape}")
        u = _inputs("u", self.u, n)
        if u.shape != (n, b.shape[1]):
            raise SettingError("u", f"inputs of shape {(n, b.shape[1])}, one row per step to match b", f"shape {u.shape}")
        if not np.all(np.isfinite(b)):
            raise SettingError("b", "finite numbers", "a non-finite value")
        if not np.all(np.isfinite(u)):
            raise SettingError("u", "finite inputs", "a non-finite value")
        diffuse = np.array(self.diffuse, dtype=bool).reshape(-1)
        if diffuse.shape != (d,):
            raise SettingError("diffuse", f"{d} flags to match phi", str(diffuse.size))
        if np.any(m0[diffuse]) or np.any(m0[:, diffuse]):
            raise SettingError("m0", "zero rows and columns for the diffuse states", show(m0))
        for name, cov in (("w", w), ("m0", m0)):
            check_covariance(name, cov)
        if n and np.min(np.linalg.eigvalsh(0.5 * (v + np.swapaxes(v, 1, 2)))) <= 0:
            raise SettingError("v", "a positive definite measurement-noise covariance at every step", "one that is not")
        times = np.array(self.times, dtype=float).reshape(-1)
        if times.shape != (n,):
            raise SettingError("times", f"{n} times, one per row", str(times.size))
        if not (np.isfinite(self.sample_period) and self.sample_period > 0):
            raise SettingError("sample_period", "a positive number", show(self.sample_period))
        for name, value in (("phi", phi), ("gamma", gamma), ("w", w), ("b", b), ("x0", x0), ("m0", m0), ("h", h),
                            ("v", v), ("u", u), ("diffuse", diffuse), ("times", times)):  # fmt: skip
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "sample_period", float(self.sample_period))

    @property
    def state_dim(self) -> int:
        """d, the number of states."""
        return self.phi.shape[0]

    @property
    def measurement_dim(self) -> int:
        """p, the number of measured components."""
        return self.h.shape[1]

    @property
    def steps(self) -> int:
        """J, the number of rows."""
        return self.h.shape[0]


def _inputs(name: str, value, rows: int) -> np.ndarray:
    """``b`` or ``u`` as a float matrix, its shape as given (the caller checks it); None or an empty
    value with fewer than 2 dimensions reads as no inputs, (rows, 0)."""
    if value is None:
        return np.zeros((rows, 0))
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise SettingError(name, "a matrix of numbers", type_name(value)) from None
    if array.size == 0 and array.ndim < 2:
        return np.zeros((rows, 0))
    if array.ndim != 2:
        raise SettingError(name, "a matrix (2 dimensions)", f"an array of shape {array.shape}")
    return array


def measured_components(model: TimeVaryingModel, z: np.ndarray) -> np.ndarray:
    """Which components of which rows are measured: z_j[i] and every entry of H_j[i] finite.

    Parameters
    ----------
    model : TimeVaryingModel
    z : ndarray, shape (J, p)

    Returns
    -------
    ndarray of bool, shape (J, p)
    """
    z = np.asarray(z, dtype=float)
    if z.shape != model.h.shape[:2]:
        raise ValueError(f"z: expected shape {model.h.shape[:2]}, got {z.shape}")
    return np.isfinite(z) & np.all(np.isfinite(model.h), axis=2)
