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
sigma_eta and sigma_nu apart are not identifiable from one log. A sample with a NaN is a prediction only.
"""

from __future__ import annotations

import numba
import numpy as np


#: the information matrix counts as nonsingular once det(Y) exceeds this share of trace(Y)^2
DIFFUSE_RCOND = 1e-12


@numba.njit(cache=True, nogil=True)
def _diffuse_filter(reference, sensor, r, q2, normalized):
    """log L, the number of samples in it, and (into ``normalized``) r_k / sqrt(S_k) (NaN elsewhere)."""
    y11 = y12 = y22 = 0.0  # Y = P^-1 while diffuse
    i1 = i2 = 0.0  # y = P^-1 x
    p11 = p12 = p22 = 0.0
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
            p11 += q2
            p22 += q2
        if not (np.isfinite(v) and np.isfinite(z)):
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
                p11, p12, p22 = y22 / det, -y12 / det, y11 / det
                x1, x2 = p11 * i1 + p12 * i2, p12 * i1 + p22 * i2
                diffuse = False
            continue
        # h = [z, 1]: S = h P h^T + R, K = P h^T / S, Joseph P^+ = (I - K h) P (I - K h)^T + K R K^T
        ph1, ph2 = p11 * z + p12, p12 * z + p22
        s = z * ph1 + ph2 + r
        e = v - (x1 * z + x2)
        g1, g2 = ph1 / s, ph2 / s
        x1 += g1 * e
        x2 += g2 * e
        a11, a12, a21, a22 = 1.0 - g1 * z, -g1, -g2 * z, 1.0 - g2
        b11, b12 = a11 * p11 + a12 * p12, a11 * p12 + a12 * p22
        b21, b22 = a21 * p11 + a22 * p12, a21 * p12 + a22 * p22
        n11 = b11 * a11 + b12 * a12 + g1 * g1 * r
        n12 = b11 * a21 + b12 * a22 + g1 * g2 * r
        n22 = b21 * a21 + b22 * a22 + g2 * g2 * r
        p11, p12, p22 = n11, n12, n22
        loglik -= 0.5 * (log2pi + np.log(s) + e * e / s)
        normalized[k] = e / np.sqrt(s)
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
