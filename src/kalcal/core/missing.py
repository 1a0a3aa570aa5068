"""The missing-measurement rule of every update: which realizations have a measurement, and the fill for the rest.

A realization whose measurement has a non-finite component (NaN marks a missing value), or whose own H
holds one, is not updated: its step is a prediction only. :func:`kalcal.core.steps.update` and
:func:`kalcal.core.sqrt_form.sqrt_update` apply this rule through one wrapper,
:func:`update_where_measured`, so that no numpy path handles a missing value its own way; the compiled
filters apply it through :func:`kalcal.core.kernels.measured`, which tests/core/test_kernel_update.py
holds to :func:`measured`.
"""

from __future__ import annotations

from typing import Callable, NamedTuple, TypeVar

import numpy as np

Result = TypeVar("Result", bound=NamedTuple)


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


def update_where_measured(
    full_update: Callable[..., Result], x: np.ndarray, factor: np.ndarray, z: np.ndarray, h: np.ndarray, *args
) -> Result:
    """A measurement update in any form, with the missing measurements a prediction only.

    ``full_update(x, factor, z, h, *args)`` is the update of every realization, returning a named tuple
    (x, factor, residual, innovation, gain): the covariance form carries P and S, the square-root form
    their factors. Where a realization's z or own H has a non-finite component, its result is the prior
    (x and the factor as given), the residual and innovation NaN and the gain 0; the others are updated
    (their z and H as given, the missing ones filled with 0 so that the batch stays finite).

    Parameters
    ----------
    full_update : callable
    x : ndarray, shape (..., d)
    factor : ndarray, shape (..., d, d)
        M, or a factor of it.
    z : ndarray, shape (..., p)
    h : ndarray, shape (p, d) or (..., p, d)
    *args
        The rest of ``full_update``'s arguments (the noise, the form).
    """
    present = measured(z, h)
    if np.all(present):
        return full_update(x, factor, z, h, *args)
    z_filled, h_filled = fill_missing(present, z, h)
    full = full_update(x, factor, z_filled, h_filled, *args)
    keep = present[..., None]
    return type(full)(
        np.where(keep, full[0], x),
        np.where(keep[..., None], full[1], factor),
        np.where(keep, full[2], np.nan),
        np.where(keep[..., None], full[3], np.nan),
        np.where(keep[..., None], full[4], 0.0),
    )
