"""The scale-bias filter's log-likelihood with a diffuse prior on theta, by the prediction-error decomposition.

The filter of :mod:`kalcal.filters.regression` (reference_k = theta1 sensor_k + theta2 + w_k, w_k ~ N(0, R),
theta a random walk with Q = q^2 I per sample) starts here from a **diffuse** prior on theta: no
information at all (P_0^{-1} = 0), the limit of N(m, kappa I) as kappa -> infinity. It runs the
information filter's start of :mod:`kalcal.core.diffuse` (compiled: :func:`kalcal.core.kernels.diffuse_start`)
until Y = P^{-1} is nonsingular, which the first two samples with different sensor readings make it,
then as the covariance filter (Joseph form). The log-likelihood is the conditional (diffuse) one: the
prediction-error decomposition over the samples after that start,

    log L = -1/2 sum_k (log 2 pi S_k + r_k^2 / S_k),

which is log p(v_{m+1..K} | v_{1..m}) and, up to a constant free of R and Q, the diffuse likelihood. With a
diffuse prior only R = sigma_eta^2 + theta1^2 sigma_nu^2 (the combined measurement noise) and q enter it:
sigma_eta and sigma_nu apart are not identifiable from one log. A sample with a NaN is a prediction only
(the compiled :func:`kalcal.core.kernels.measured`); after the start, each update is the package's one
compiled covariance update, :func:`kalcal.core.kernels.covariance_update`, on a tile of one realization.
The compiled path is held step by step (P, r_k, S_k and log L) to the numpy reference, the diffuse start
then :func:`kalcal.filters.regression.run_regression_filter` then
:func:`kalcal.core.likelihood.innovation_loglik` (tests/fitting/test_scale_bias_likelihood_steps.py).
"""

# numba cache stamp: kalcal.core.kernels a5dbbb626c1a87c1

from __future__ import annotations

import numba
import numpy as np

from kalcal.core.diffuse import DIFFUSE_RCOND
from kalcal.core.kernels import covariance_update, diffuse_start, measured, update_work


@numba.njit(cache=True, nogil=True)
def _diffuse_filter(reference, sensor, r, q2, normalized, record, covs, residual, innovation_var):
    """log L, the number of samples in it, and (into ``normalized``) r_k / sqrt(S_k) (NaN elsewhere).

    With ``record``, P_k^+ (from the start's last sample on), r_k and S_k go into ``covs`` (K, 2, 2),
    ``residual`` and ``innovation_var`` (K,) (NaN where there is none), for the step-by-step test; without
    it those may be empty."""
    n = reference.size
    for k in range(n):
        normalized[k] = np.nan
    if record:
        for k in range(n):
            residual[k] = innovation_var[k] = np.nan
            for i in range(2):
                for j in range(2):
                    covs[k, i, j] = np.nan
    rows = np.empty((n, 2))  # h_k = [z_k, 1]
    for k in range(n):
        rows[k, 0], rows[k, 1] = sensor[k], 1.0
    q = np.zeros((2, 2))
    q[0, 0] = q[1, 1] = q2
    x, start_cov = np.empty(2), np.empty((2, 2))
    start = diffuse_start(reference, rows, r, q, DIFFUSE_RCOND, x, start_cov)
    if start == 0:  # theta never determined: no sample has an innovation
        return 0.0, 0
    # after the diffuse start: P as a tile of one realization, for the one compiled covariance update
    cov = np.empty((2, 2, 1))
    for i in range(2):
        for j in range(2):
            cov[i, j, 0] = start_cov[i, j]
            if record:
                covs[start - 1, i, j] = start_cov[i, j]
    row = np.ones((1, 2, 1))
    noise = np.full((1, 1), r)
    gain, s, work = np.empty((1, 2, 1)), np.empty((1, 1, 1)), update_work(2, 1, 1)
    v_k = np.empty(1)  # the measurement v_k (its regressor is row)
    x1, x2 = x[0], x[1]
    loglik, used = 0.0, 0
    log2pi = np.log(2.0 * np.pi)
    for k in range(start, n):
        v, z = reference[k], sensor[k]
        cov[0, 0, 0] += q2  # the prediction: P^- = P^+ + Q
        cov[1, 1, 0] += q2
        v_k[0], row[0, 0, 0] = v, z
        if measured(v_k, row[:, :, 0]):  # else the one missing-measurement rule: a prediction only
            # S = h P h^T + R, K = P h^T / S and the Joseph-form P^+: the one compiled covariance update
            e = v - (x1 * z + x2)
            covariance_update(cov, row, noise, True, gain, s, work)
            x1 += gain[0, 0, 0] * e
            x2 += gain[0, 1, 0] * e
            loglik -= 0.5 * (log2pi + np.log(s[0, 0, 0]) + e * e / s[0, 0, 0])
            normalized[k] = e / np.sqrt(s[0, 0, 0])
            used += 1
            if record:
                residual[k], innovation_var[k] = e, s[0, 0, 0]
        if record:
            for i in range(2):
                for j in range(2):
                    covs[k, i, j] = cov[i, j, 0]
    return loglik, used


def diffuse_loglik(reference: np.ndarray, sensor: np.ndarray, noise_std: float, drift_std: float) -> tuple[float, int, np.ndarray]:
    """The conditional log-likelihood of a scale-bias log under a diffuse prior on theta.

    Parameters
    ----------
    reference, sensor : ndarray, shape (K,)
        v_k and z_k, signal unit; NaN marks a missing value.
    noise_std : float
        sqrt(R), the combined measurement noise sqrt(sigma_eta^2 + theta1^2 sigma_nu^2), signal unit, > 0.
    drift_std : float
        q, the random walk's std per sample of theta1 (1) and theta2 (signal unit), >= 0.

    Returns
    -------
    loglik : float
    samples : int
        The samples in the likelihood (those after the diffuse start).
    normalized : ndarray, shape (K,)
        r_k / sqrt(S_k) for those samples, NaN elsewhere.
    """
    if not noise_std > 0 or not drift_std >= 0:
        raise ValueError(f"expected noise_std > 0 and drift_std >= 0, got {noise_std!r}, {drift_std!r}")
    reference = np.ascontiguousarray(reference, dtype=float)
    sensor = np.ascontiguousarray(sensor, dtype=float)
    normalized = np.empty(reference.size)
    empty = np.empty(0)
    loglik, used = _diffuse_filter(
        reference, sensor, float(noise_std) ** 2, float(drift_std) ** 2, normalized, False, np.empty((0, 2, 2)), empty, empty
    )
    return float(loglik), int(used), normalized


def diffuse_filter_steps(reference: np.ndarray, sensor: np.ndarray, noise_std: float, drift_std: float) -> dict:
    """The compiled path of :func:`diffuse_loglik` step by step, for its test against the numpy reference.

    Returns
    -------
    dict
        ``loglik``, ``samples``, ``normalized`` as :func:`diffuse_loglik`; ``cov`` P_k^+ (K, 2, 2) from the
        start's last sample on (NaN before), ``residual`` r_k and ``innovation_var`` S_k (K,) (NaN where
        the sample has no innovation).
    """
    reference = np.ascontiguousarray(reference, dtype=float)
    sensor = np.ascontiguousarray(sensor, dtype=float)
    n = reference.size
    normalized, covs, residual, innovation = np.empty(n), np.empty((n, 2, 2)), np.empty(n), np.empty(n)
    loglik, used = _diffuse_filter(
        reference, sensor, float(noise_std) ** 2, float(drift_std) ** 2, normalized, True, covs, residual, innovation
    )
    return {"loglik": float(loglik), "samples": int(used), "normalized": normalized, "cov": covs,
            "residual": residual, "innovation_var": innovation}
