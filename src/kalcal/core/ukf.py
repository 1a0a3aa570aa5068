"""The unscented Kalman filter with Van der Merwe's scaled sigma points, batched over realizations.

Sigma points of (x, P) in d dimensions, lambda = alpha^2 (d + kappa) - d, L L^T = (d + lambda) P by
Cholesky::

    chi_0 = x,   chi_i = x + L[:, i-1],   chi_{d+i} = x - L[:, i-1]          (i = 1..d)
    Wm_0 = lambda / (d + lambda),   Wc_0 = Wm_0 + 1 - alpha^2 + beta,   Wm_i = Wc_i = 1 / (2 (d + lambda))

predict:  Y_i = f(chi_i(xhat, P), u, dt),   xbar = sum Wm_i Y_i,   M = sum Wc_i (Y_i - xbar)(Y_i - xbar)^T + Q
update:   chi_i = chi_i(xbar, M) (drawn anew, so that Q's spread enters h),   Z_i = h(chi_i, data)
          zbar = sum Wm_i Z_i,   S = sum Wc_i (Z_i - zbar)(...)^T + R,   C = sum Wc_i (chi_i - xbar)(Z_i - zbar)^T
          K = C S^{-1} (a solve with S),   r = z - zbar,   xhat = xbar + K r,   P = M - K S K^T

Defaults alpha = 1, beta = 2, kappa = 0 (:class:`UnscentedSettings`): with alpha = 1 the weights are
all of one sign except Wc_0 = 2, while the often quoted alpha = 1e-3 gives Wm_0 = 1 - d / (alpha^2 (d +
kappa)) ~ -4 10^6 at d = 4, and the mean and covariance lose about six digits to the cancellation
(tests/core/test_nonlinear_filters.py holds alpha = 1 to the linear filter at 1e-10, a small alpha at 1e-8).

A realization with a non-finite component of z keeps its prior (r and S NaN, K 0), as in every update.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kalcal.core.missing import measured
from kalcal.core.nonlinear import NonlinearModel
from kalcal.core.steps import UpdateResult
from kalcal.errors import ConfigError
from kalcal.linalg import matvec, symmetrize

__all__ = ["UnscentedSettings", "sigma_points", "ukf_predict", "ukf_update"]


@dataclass(frozen=True)
class UnscentedSettings:
    """Van der Merwe's scaled sigma points: alpha (spread, 0 < alpha <= 1), beta (2: Gaussian prior), kappa.

    d + lambda = alpha^2 (d + kappa) must be positive.
    """

    alpha: float = 1.0
    beta: float = 2.0
    kappa: float = 0.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.alpha) and 0 < self.alpha <= 1):
            raise ConfigError(f"alpha: expected a number in (0, 1], got {self.alpha!r}")
        for name in ("beta", "kappa"):
            if not np.isfinite(getattr(self, name)):
                raise ConfigError(f"{name}: expected a finite number, got {getattr(self, name)!r}")

    def weights(self, d: int) -> tuple[np.ndarray, np.ndarray, float]:
        """Wm (2d+1,), Wc (2d+1,) and the points' scale d + lambda."""
        spread = self.alpha**2 * (d + self.kappa)
        if spread <= 0:
            raise ConfigError(f"kappa: alpha^2 (d + kappa) must be positive, got {spread!r} for d = {d}")
        lam = spread - d
        wm = np.full(2 * d + 1, 0.5 / spread)
        wc = wm.copy()
        wm[0] = lam / spread
        wc[0] = wm[0] + 1.0 - self.alpha**2 + self.beta
        return wm, wc, spread


def sigma_points(x: np.ndarray, cov: np.ndarray, spread: float) -> np.ndarray:
    """The 2d + 1 points x, x +- columns of L, L L^T = spread * P (Cholesky): (n, d), (n, d, d) -> (n, 2d+1, d)."""
    cols = np.swapaxes(np.linalg.cholesky(spread * cov), -1, -2)  # row i is L's column i
    centre = x[:, None, :]
    return np.concatenate([centre, centre + cols, centre - cols], axis=1)


def _repeat(value: np.ndarray | None, count: int) -> np.ndarray | None:
    """A per-realization input (n, k) repeated for each of a realization's ``count`` points; a shared one as is."""
    if value is None:
        return None
    value = np.asarray(value, dtype=float)
    return np.repeat(value, count, axis=0) if value.ndim == 2 else value


def _moments(points: np.ndarray, wm: np.ndarray, wc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    mean = np.einsum("s,nsi->ni", wm, points)
    dev = points - mean[:, None, :]
    return mean, np.einsum("s,nsi,nsj->nij", wc, dev, dev)


def ukf_predict(
    model: NonlinearModel,
    x: np.ndarray,
    cov: np.ndarray,
    u: np.ndarray | None = None,
    settings: UnscentedSettings = UnscentedSettings(),
) -> tuple[np.ndarray, np.ndarray]:
    """The unscented transform of (x, P) through f, plus Q: (n, d), (n, d, d) -> xbar (n, d), M (n, d, d)."""
    n, d = x.shape
    wm, wc, spread = settings.weights(d)
    points = sigma_points(x, cov, spread)
    moved = model.transition(points.reshape(n * (2 * d + 1), d), _repeat(u, 2 * d + 1)).reshape(points.shape)
    mean, spread_cov = _moments(moved, wm, wc)
    return mean, symmetrize(spread_cov + model.q)


def ukf_update(
    model: NonlinearModel,
    x: np.ndarray,
    cov: np.ndarray,
    z: np.ndarray,
    data: np.ndarray | None = None,
    settings: UnscentedSettings = UnscentedSettings(),
) -> UpdateResult:
    """The unscented update of a prior (xbar, M) with z (module docstring).

    Parameters
    ----------
    model : NonlinearModel
    x : ndarray, shape (n, d)
    cov : ndarray, shape (n, d, d)
    z : ndarray, shape (p,) or (n, p)
    data : ndarray, shape (k,) or (n, k), or None
    settings : UnscentedSettings

    Returns
    -------
    UpdateResult
        x (n, d), cov P (n, d, d), residual r = z - zbar (n, p), innovation_cov S (n, p, p), gain K (n, d, p).
    """
    n, d = x.shape
    p = model.measurement_dim
    wm, wc, spread = settings.weights(d)
    points = sigma_points(x, cov, spread)
    images = model.measure(points.reshape(n * (2 * d + 1), d), _repeat(data, 2 * d + 1)).reshape(n, 2 * d + 1, p)
    zbar, spread_s = _moments(images, wm, wc)
    s = symmetrize(spread_s + model.r)
    cross = np.einsum("s,nsi,nsj->nij", wc, points - x[:, None, :], images - zbar[:, None, :])
    # K^T = S^{-1} C^T: a solve with S, never its inverse
    gain = np.swapaxes(np.linalg.solve(s, np.swapaxes(cross, -1, -2)), -1, -2)
    residual = np.broadcast_to(np.asarray(z, dtype=float), (n, p)) - zbar
    present = measured(residual, np.zeros((1, 1)))
    filled = np.where(present[:, None], residual, 0.0)
    posterior = symmetrize(cov - gain @ s @ np.swapaxes(gain, -1, -2))
    keep = present[:, None]
    return UpdateResult(
        np.where(keep, x + matvec(gain, filled), x),
        np.where(keep[..., None], posterior, cov),
        np.where(keep, residual, np.nan),
        np.where(keep[..., None], s, np.nan),
        np.where(keep[..., None], gain, 0.0),
    )
