"""The square-root form's factor algebra: tria, factors of given covariances, and the Gram matrix L L^T.

The square-root steps (:func:`~kalcal.filters.steps.sqrt_predict`,
:func:`~kalcal.filters.steps.sqrt_update`) carry a lower-triangular factor L with P = L L^T and never form
P to factor it again. With tria(A) the lower-triangular T, diagonal >= 0, such that T T^T = A A^T (from a
QR decomposition of A^T), every step is one tria of a pre-array.
"""

from __future__ import annotations

import numpy as np

from kalcal.linalg import symmetrize


def triangularize(a: np.ndarray) -> np.ndarray:
    """tria(A): the lower-triangular T with T T^T = A A^T and a non-negative diagonal.

    From the QR decomposition A^T = Q R: A A^T = R^T R, so T = R^T with the signs of R's rows flipped
    where its diagonal is negative. Unique where A A^T is positive definite (its Cholesky factor).

    Parameters
    ----------
    a : ndarray, shape (..., d, n)
        Any n >= 0; fewer columns than rows are padded with zeros.

    Returns
    -------
    ndarray, shape (..., d, d)
    """
    a = np.asarray(a, dtype=float)
    d, n = a.shape[-2:]
    if n < d:
        a = np.concatenate([a, np.zeros(a.shape[:-1] + (d - n,))], axis=-1)
    r = np.linalg.qr(np.swapaxes(a, -1, -2), mode="r")
    sign = np.where(np.diagonal(r, axis1=-2, axis2=-1) < 0, -1.0, 1.0)
    return np.swapaxes(r * sign[..., :, None], -1, -2)


def cholesky_factor(cov: np.ndarray) -> np.ndarray:
    """A lower-triangular L with L L^T = cov, for the given covariances (M0, Q, V) of the square-root form.

    The Cholesky factor where ``cov`` is positive definite; otherwise (a singular Q, such as a state that
    receives no process noise) from the eigendecomposition, clipped at zero and triangularized. Never
    applied to the filter's own posterior: the square-root form carries its factor from step to step.

    Parameters
    ----------
    cov : ndarray, shape (..., d, d), symmetric positive semi-definite

    Returns
    -------
    ndarray, shape (..., d, d)
    """
    cov = symmetrize(np.asarray(cov, dtype=float))
    try:
        return np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        values, vectors = np.linalg.eigh(cov)
        return triangularize(vectors * np.sqrt(np.clip(values, 0.0, None))[..., None, :])


def gram(chol: np.ndarray) -> np.ndarray:
    """L L^T over the last two axes, symmetrized: the covariance a square-root factor stands for.

    Parameters
    ----------
    chol : ndarray, shape (..., d, r)

    Returns
    -------
    ndarray, shape (..., d, d)
    """
    return symmetrize(chol @ np.swapaxes(chol, -1, -2))


def broadcast_lead(*arrays: np.ndarray) -> list[np.ndarray]:
    """Broadcast the leading (batch) axes of matrices, keeping each one's last two axes."""
    lead = np.broadcast_shapes(*(a.shape[:-2] for a in arrays))
    return [np.broadcast_to(a, lead + a.shape[-2:]) for a in arrays]
