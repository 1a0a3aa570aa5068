"""Small dense linear-algebra helpers shared by the numeric layers."""

from __future__ import annotations

import numpy as np


def symmetrize(matrix: np.ndarray) -> np.ndarray:
    """(A + A^T) / 2 over the last two axes."""
    return 0.5 * (matrix + np.swapaxes(matrix, -1, -2))


def matvec(matrix: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """A x over the leading (batch) axes: matrix (..., m, n), vector (..., n) -> (..., m)."""
    return (matrix @ vector[..., None])[..., 0]


def psd_factor(cov: np.ndarray, *, rtol: float = 1e-12) -> np.ndarray:
    """A factor L with L L^T = cov for a symmetric positive semi-definite matrix.

    Directions with eigenvalue below ``rtol`` times the largest are dropped, so a rank-r covariance
    gives a (d, r) factor and a draw L xi needs only r standard normals.

    Parameters
    ----------
    cov : ndarray, shape (d, d)

    Returns
    -------
    ndarray, shape (d, r)
    """
    values, vectors = np.linalg.eigh(symmetrize(np.asarray(cov, dtype=float)))
    largest = values.max(initial=0.0)
    keep = values > rtol * largest if largest > 0 else np.zeros(values.shape, dtype=bool)
    return vectors[:, keep] * np.sqrt(values[keep])


def whitener(cov: np.ndarray) -> np.ndarray:
    """W with W^T W = cov^{-1}, so that |W e|^2 = e^T cov^{-1} e, by a Cholesky factor.

    Parameters
    ----------
    cov : ndarray, shape (..., d, d), positive definite

    Returns
    -------
    ndarray, shape (..., d, d): the inverse of the lower Cholesky factor.
    """
    lower = np.linalg.cholesky(cov)
    eye = np.broadcast_to(np.eye(cov.shape[-1]), cov.shape)
    return np.linalg.solve(lower, eye)
