"""The scale/bias parametrization theta = [1 / (1 - a), b / (1 - a)], both ways, and its Gaussian prior.

The filter of :mod:`kalcal.scenarios.scale_bias.settings` estimates theta; the sensor's datasheet (and the settings)
speak of the scale-factor error a (1) and the bias b (signal unit). The prior of theta is the first-order
image of independent Gaussian priors of a and b.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class ThetaPrior(NamedTuple):
    """A Gaussian prior of theta = [theta1, theta2]."""

    mean: np.ndarray  #: (2,), [1, signal unit]
    cov: np.ndarray  #: (2, 2)


def theta_from_scale_bias(a, b) -> np.ndarray:
    """theta = [1 / (1 - a), b / (1 - a)], shape (..., 2) for a, b of shape (...)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    gain = 1.0 - a
    return np.stack(np.broadcast_arrays(1.0 / gain, b / gain), axis=-1)


def scale_bias_from_theta(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """a = 1 - 1 / theta1 and b = theta2 / theta1 for theta of shape (..., 2)."""
    theta = np.asarray(theta, dtype=float)
    return 1.0 - 1.0 / theta[..., 0], theta[..., 1] / theta[..., 0]


def scale_bias_jacobian(theta: np.ndarray) -> np.ndarray:
    """d(a, b) / d(theta1, theta2) = [[1 / theta1^2, 0], [-theta2 / theta1^2, 1 / theta1]], shape (..., 2, 2)."""
    theta = np.asarray(theta, dtype=float)
    t1, t2 = theta[..., 0], theta[..., 1]
    jac = np.zeros(theta.shape[:-1] + (2, 2))
    jac[..., 0, 0] = 1.0 / t1**2
    jac[..., 1, 0] = -t2 / t1**2
    jac[..., 1, 1] = 1.0 / t1
    return jac


def theta_prior(a: float, a_std: float, b: float, b_std: float) -> ThetaPrior:
    """The Gaussian prior of theta from the moments of a and b, to first order.

    mean = theta(a, b); cov = J diag(a_std^2, b_std^2) J^T with J = d theta / d(a, b) at the mean:
    J = [[1 / (1 - a)^2, 0], [b / (1 - a)^2, 1 / (1 - a)]].
    """
    gain = 1.0 - a
    jac = np.array([[1.0 / gain**2, 0.0], [b / gain**2, 1.0 / gain]])
    cov = jac @ np.diag([a_std**2, b_std**2]) @ jac.T
    return ThetaPrior(theta_from_scale_bias(a, b), 0.5 * (cov + cov.T))
