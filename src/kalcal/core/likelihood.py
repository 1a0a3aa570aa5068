"""The log-likelihood of a filter's innovations: the prediction-error decomposition."""

from __future__ import annotations

import numpy as np

__all__ = ["gate_excess", "innovation_loglik"]


def innovation_loglik(residual: np.ndarray, innovation_cov: np.ndarray, *, skip: int = 0) -> float:
    """log L = -1/2 sum_k (log det S_k + r_k^T S_k^{-1} r_k + p log 2 pi) over the fixes used.

    For a linear-Gaussian model the filter's innovations r_k ~ N(0, S_k) are independent, so this is the
    exact log-density of the measurements (the prediction-error decomposition). A row with a non-finite
    residual (a missing fix, or one the innovation gate rejected, entered as NaN) contributes nothing:
    the density is then that of the fixes used, each conditioned on the used ones before it.

    Parameters
    ----------
    residual : ndarray, shape (K, p)
        r_k = z_k - H xbar_k.
    innovation_cov : ndarray, shape (K, p, p)
        S_k, symmetric positive definite where the residual is finite.
    skip : int
        Leave out the first ``skip`` rows: the conditional likelihood given those fixes (the diffuse form,
        where a diffuse prior makes the first fixes' terms meaningless).

    Returns
    -------
    float
        log L (natural log); 0.0 when no row is left.
    """
    residual = np.asarray(residual, dtype=float)
    innovation_cov = np.asarray(innovation_cov, dtype=float)
    if residual.ndim != 2 or innovation_cov.shape != residual.shape + residual.shape[-1:]:
        raise ValueError(f"expected residual (K, p) and innovation_cov (K, p, p), got {residual.shape} and {innovation_cov.shape}")
    if skip < 0:
        raise ValueError(f"skip: expected a number of fixes >= 0, got {skip!r}")
    residual, innovation_cov = residual[skip:], innovation_cov[skip:]
    used = np.all(np.isfinite(residual), axis=1)
    r, s = residual[used], innovation_cov[used]
    if r.shape[0] == 0:
        return 0.0
    if r.shape[1] == 2:  # a two-row measurement (a position fix): the 2x2 determinant and inverse in closed form, ten times faster
        a, b, c = s[:, 0, 0], s[:, 1, 1], 0.5 * (s[:, 0, 1] + s[:, 1, 0])
        det = a * b - c * c
        quad = (b * r[:, 0] ** 2 - 2.0 * c * r[:, 0] * r[:, 1] + a * r[:, 1] ** 2) / det
        return float(-0.5 * (np.sum(np.log(det)) + np.sum(quad) + r.size * np.log(2.0 * np.pi)))
    lower = np.linalg.cholesky(s)
    white = np.linalg.solve(lower, r[..., None])[..., 0]
    log_det = 2.0 * np.sum(np.log(np.diagonal(lower, axis1=1, axis2=2)))
    return float(-0.5 * (log_det + np.sum(white * white) + r.size * np.log(2.0 * np.pi)))


def gate_excess(rejected: int, gated: int, gate: float) -> str:
    """A sentence when an innovation gate rejected far more of ``gated`` fixes than its (1 - gate) share:
    more than the share's mean plus 3 binomial standard deviations plus 3 fixes; "" otherwise.

    Parameters
    ----------
    rejected, gated : int
        The fixes rejected, and the fixes the gate judged (rejected ones included).
    gate : float
        The gate's confidence, in (0, 1).
    """
    share = 1.0 - gate
    limit = gated * share + 3.0 * np.sqrt(gated * share * gate) + 3.0
    if rejected <= limit:
        return ""
    return (
        f"the gate rejected {rejected} of {gated} fixes, far more than its {share:.3g} share ({limit:.0f} at most "
        "for settings that describe the fixes)"
    )
