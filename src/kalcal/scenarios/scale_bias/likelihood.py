"""The scale-bias filter's log-likelihood with a diffuse prior on theta, by the prediction-error decomposition.

The filter of :mod:`kalcal.filters.regression` (reference_k = theta1 sensor_k + theta2 + w_k, w_k ~ N(0, R),
theta a random walk with Q = q^2 I per sample) starts here from a **diffuse** prior on theta: no
information at all (P_0^{-1} = 0), the limit of N(m, kappa I) as kappa -> infinity. It runs in information
form (Y = P^{-1}, y = P^{-1} x; the prediction Y^- = (I + q^2 Y)^{-1} Y, y^- = (I + q^2 Y)^{-1} y, the update
Y += h h^T / R, y += h v / R) until Y is nonsingular, which the first two samples with different sensor
readings make it, then as the covariance filter (Joseph form). The log-likelihood is the conditional
(diffuse) one: the prediction-error decomposition over the samples after that start,

    log L = -1/2 sum_k (log 2 pi S_k + r_k^2 / S_k),

which is log p(v_{m+1..K} | v_{1..m}) and, up to a constant free of R and Q, the diffuse likelihood. With a
diffuse prior only R = sigma_eta^2 + theta1^2 sigma_nu^2 (the combined measurement noise) and q enter it:
sigma_eta and sigma_nu apart are not identifiable from one log. A sample with a NaN is a prediction only
(the compiled :func:`kalcal.core.kernels.measured`); after the start, each update is the package's one
compiled covariance update, :func:`kalcal.core.kernels.covariance_update`, on a tile of one realization.
"""

# numba cache stamp: kalcal.core.kernels a06579bff82c7382

from __future__ import annotations

import numba
import numpy as np

from kalcal.core.kernels import covariance_update, measured, update_work


#: the information matrix counts as nonsingular once det(Y) exceeds this share of trace(Y)^2
DIFFUSE_RCOND = 1e-12


@numba.njit(cache=True, nogil=True)
def _diffuse_filter(reference, sensor, r, q2, normalized):
    """log L, the number of samples in it, and (into ``normalized``) r_k / sqrt(S_k) (NaN elsewhere)."""
    y11 = y12 = y22 = 0.0  # Y = P^-1 while diffuse
    i1 = i2 = 0.0  # y = P^-1 x
    # after the diffuse start: P as a tile of one realization, for the one compiled covariance update
    cov = np.zeros((2, 2, 1))
    row = np.ones((1, 2, 1))  # h = [z, 1]
    noise = np.full((1, 1), r)
    gain, s, work = np.empty((1, 2, 1)), np.empty((1, 1, 1)), update_work(2, 1, 1)
    v_k = np.empty(1)  # the measurement v_k (its regressor is row)
    x1 = x2 = 0.0
    diffuse = True
    loglik, used = 0.0, 0
    log2pi = np.log(2.0 * np.pi)
    for k in range(reference.size):
        normalized[k] = np.nan
        v, z = reference[k], sensor[k]
        # the prediction: P^- = P^+ + Q, or in information form Y^- = (I + Q Y)^-1 Y
        if diffuse:
            if q2 > 0.0:
                a11, a12, a21, a22 = 1.0 + q2 * y11, q2 * y12, q2 * y12, 1.0 + q2 * y22
                det = a11 * a22 - a12 * a21
                m11, m12, m21, m22 = a22 / det, -a12 / det, -a21 / det, a11 / det
                y11, y12, y22 = m11 * y11 + m12 * y12, m11 * y12 + m12 * y22, m21 * y12 + m22 * y22
                i1, i2 = m11 * i1 + m12 * i2, m21 * i1 + m22 * i2
        else:
            cov[0, 0, 0] += q2
            cov[1, 1, 0] += q2
        v_k[0], row[0, 0, 0] = v, z
        if not measured(v_k, row[:, :, 0]):  # the one missing-measurement rule: a prediction only
            continue
        if diffuse:
            y11 += z * z / r
            y12 += z / r
            y22 += 1.0 / r
            i1 += z * v / r
            i2 += v / r
            det = y11 * y22 - y12 * y12
            trace = y11 + y22
            if det > DIFFUSE_RCOND * trace * trace:
                cov[0, 0, 0], cov[1, 1, 0] = y22 / det, y11 / det
                cov[0, 1, 0] = cov[1, 0, 0] = -y12 / det
                x1 = cov[0, 0, 0] * i1 + cov[0, 1, 0] * i2
                x2 = cov[0, 1, 0] * i1 + cov[1, 1, 0] * i2
                diffuse = False
            continue
        # S = h P h^T + R, K = P h^T / S and the Joseph-form P^+: the one compiled covariance update
        e = v - (x1 * z + x2)
        covariance_update(cov, row, noise, True, gain, s, work)
        x1 += gain[0, 0, 0] * e
        x2 += gain[0, 1, 0] * e
        loglik -= 0.5 * (log2pi + np.log(s[0, 0, 0]) + e * e / s[0, 0, 0])
        normalized[k] = e / np.sqrt(s[0, 0, 0])
        used += 1
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
    loglik, used = _diffuse_filter(reference, sensor, float(noise_std) ** 2, float(drift_std) ** 2, normalized)
    return float(loglik), int(used), normalized
