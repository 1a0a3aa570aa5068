"""One realization of the ensemble as the single-run figures show it: data only, without matplotlib.

The jobs build it in a process that need not load the plotting code.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class RealizationData:
    """One realization of the ensemble, at the K update times. d states.

    Attributes
    ----------
    index : int
        Which realization of the ensemble (0-based).
    times : ndarray, shape (K,)
        Update times, s.
    truth : ndarray, shape (K, d)
        True state x_k (for the accelerometer/GPS scenario: p - p_c (m), v - v_c (m/s), b (m/s^2)).
    estimate : ndarray, shape (K, d)
        Filter estimate xhat_k (a posteriori), same units.
    error : ndarray, shape (K, d)
        e_k = x_k - xhat_k, same units.
    filter_cov : ndarray, shape (K, d, d)
        The filter's covariance P_k of e_k.
    state_names, state_units : tuple of str, length d
    state_labels : tuple of str, length d, optional
        What each state is, for the figures (accel-gps: ``δp = p − p_c``, ``δv = v − v_c``, ``b``: error
        states of the nominal, not the position and velocity); the names where not given.
    """

    index: int
    times: np.ndarray
    truth: np.ndarray
    estimate: np.ndarray
    error: np.ndarray
    filter_cov: np.ndarray
    state_names: tuple[str, ...]
    state_units: tuple[str, ...]
    state_labels: tuple[str, ...] | None = None

    def state_label(self, state: int) -> str:
        """The label of state ``state`` (its name where no labels are given)."""
        return self.state_names[state] if self.state_labels is None else self.state_labels[state]

    def sigma(self, state: int) -> np.ndarray:
        """sqrt(P_k[i, i]) of state ``state``, (K,)."""
        return np.sqrt(self.filter_cov[:, state, state])
