"""The missing-measurement rule of every update: which realizations have a measurement, and the fill for the rest.

A realization whose measurement has a non-finite component (NaN marks a missing value), or whose own H
holds one, is not updated: its step is a prediction only. :func:`kalcal.filters.steps.update` and
:func:`kalcal.filters.sqrt_form.sqrt_update` apply this rule through :func:`measured` and
:func:`fill_missing`, so that no numpy path handles a missing value its own way.
"""

from __future__ import annotations

import numpy as np


def measured(z: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Which realizations have a measurement: every component of z and every entry of H finite.

    Parameters
    ----------
    z : ndarray, shape (..., p)
    h : ndarray, shape (p, d) or (..., p, d)

    Returns
    -------
    ndarray of bool, shape (...) (the broadcast of z's and H's leading axes)
    """
    return np.all(np.isfinite(z), axis=-1) & np.all(np.isfinite(h), axis=(-2, -1))


def fill_missing(present: np.ndarray, z: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """z and H with the missing realizations' entries set to 0, so that their update stays finite."""
    return np.where(present[..., None], z, 0.0), np.where(present[..., None, None], h, 0.0)
