"""The information filter's start for a diffuse state: no information at all until the measurements determine it.

A diffuse prior (P_0^{-1} = 0, the limit of N(m, kappa I) as kappa -> infinity) has no covariance, so
the filter starts in information form, Y = P^{-1} and y = P^{-1} x, both 0 at the start. For a random
walk (Phi = I, process noise Q per step) and scalar measurements v_k = h_k x_k + w_k, w_k ~ N(0, R),
each step is::

    predict:  Y^- = (I + Q Y)^{-1} Y,   y^- = (I + Q Y)^{-1} y      (the information form of M = P + Q)
    update:   Y^+ = Y^- + h_k^T h_k / R,   y^+ = y^- + h_k^T v_k / R

until Y is nonsingular, det(Y) > rcond trace(Y)^d (d the state's size), after m samples; then
P_m = Y^{-1} and x_m = P_m y, from which the covariance filter goes on (sample m + 1 is its first
update, and the first with an innovation). A measurement that is missing (a non-finite v_k or h_k:
:func:`kalcal.core.missing.measured`) is a prediction only. (I + Q Y) is solved, never inverted.

:func:`diffuse_start` is the numpy reference; :func:`kalcal.core.kernels.diffuse_start` is its compiled
twin, which the compiled diffuse likelihood runs and tests/core/test_diffuse.py holds to this one.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from kalcal.core.missing import measured
from kalcal.linalg import symmetrize

__all__ = ["DIFFUSE_RCOND", "DiffuseStart", "diffuse_start"]

#: the information matrix counts as nonsingular once det(Y) exceeds this share of trace(Y)^d
DIFFUSE_RCOND = 1e-12


class DiffuseStart(NamedTuple):
    """Where the information filter hands over to the covariance filter."""

    samples: int  #: m, the samples the start took (sample m, 1-based, is its last)
    x: np.ndarray  #: x_m^+ = P_m y_m, (d,)
    cov: np.ndarray  #: P_m^+ = Y_m^{-1}, (d, d), symmetric


def diffuse_start(
    y: np.ndarray, h: np.ndarray, r: float, q: np.ndarray, rcond: float = DIFFUSE_RCOND
) -> DiffuseStart | None:
    """Run the information filter from no information until the state is determined.

    Parameters
    ----------
    y : ndarray, shape (K,)
        The scalar measurements v_k; NaN marks a missing one.
    h : ndarray, shape (K, d)
        Their regressor rows h_k; a row with a NaN is a missing measurement.
    r : float
        The measurement-noise variance R > 0, in y's unit squared.
    q : ndarray, shape (d, d)
        The random walk's process-noise covariance per step (zeros: a constant state).
    rcond : float
        Y counts as nonsingular once det(Y) > rcond trace(Y)^d.

    Returns
    -------
    DiffuseStart, or None when the measurements never determine the state.
    """
    y = np.asarray(y, dtype=float)
    h = np.asarray(h, dtype=float)
    q = np.asarray(q, dtype=float)
    n, d = h.shape
    if y.shape != (n,):
        raise ValueError(f"y: expected shape ({n},) to match h {h.shape}, got {y.shape}")
    present = measured(y[:, None], h[:, None, :])  # the one missing-measurement rule
    info, vector = np.zeros((d, d)), np.zeros(d)
    drift = bool(np.any(q))
    for k in range(n):
        if drift:  # Y^- = (I + Q Y)^{-1} Y, y^- = (I + Q Y)^{-1} y, by one solve
            solved = np.linalg.solve(np.eye(d) + q @ info, np.column_stack([info, vector]))
            info, vector = symmetrize(solved[:, :d]), solved[:, d]
        if not present[k]:
            continue
        info = info + np.outer(h[k], h[k]) / r
        vector = vector + h[k] * y[k] / r
        if np.linalg.det(info) > rcond * np.trace(info) ** d:
            cov = symmetrize(np.linalg.solve(info, np.eye(d)))
            return DiffuseStart(k + 1, cov @ vector, cov)
    return None
