"""Realizations of the two-sensor scale/bias scenario.

Every sample is a measurement, so simulating per sample is already exact: there is no dynamics between
samples to sum over. For n realizations the draws are made in one fixed order, realization index first:

1. ``(n, 2)``: theta_0 = mean + L xi for the truth's prior N(mean, L L^T);
2. ``(n, K, 2)``: the random-walk increments omega_0..omega_{K-1}, only when ``scenario.drift`` is
   ``"random-walk"``; theta_k = theta_0 + omega_0 + ... + omega_{k-1} for the sample k = 1..K;
3. ``(n, K)``: the reference noise eta_k / sigma_eta;
4. ``(n, K)``: the sensor noise nu_k / sigma_nu (drawn even when sigma_nu = 0, so that the stream does
   not depend on it).

With the profile s_k = s(t_k) (see :class:`~kalcal.scenarios.scale_bias.settings.ScaleBiasScenario`):
``excitation = "sensor"``: zeta_k = s_k, psi_k = theta1_k s_k + theta2_k;
``excitation = "reference"``: psi_k = s_k, zeta_k = (s_k - theta2_k) / theta1_k; then
v_k = psi_k + eta_k and z_k = zeta_k - nu_k (zeta = (1 - a) psi - b is the sensor's noise-free reading).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kalcal.linalg import psd_factor
from kalcal.scenarios.scale_bias.settings import ScaleBiasScenario


@dataclass(frozen=True)
class ScaleBiasSamples:
    """n realizations of K samples. Signal quantities in ``scenario.unit``."""

    time: np.ndarray  #: t_k, s, (K,)
    theta: np.ndarray  #: true [theta1, theta2] at each sample, (n, K, 2)
    psi: np.ndarray  #: the measured quantity psi_k, (n, K)
    clean_sensor: np.ndarray  #: zeta_k, the sensor's noise-free reading, (n, K)
    reference: np.ndarray  #: v_k = psi_k + eta_k, (n, K)
    sensor: np.ndarray  #: z_k = zeta_k - nu_k, (n, K)


def normals_per_realization(scenario: ScaleBiasScenario) -> int:
    """Standard normals one realization draws: 2 + 2 K, plus 2 K with drift."""
    k = scenario.scenario.n_samples
    return 2 + 2 * k + (2 * k if scenario.scenario.drift == "random-walk" else 0)


def sample_scale_bias(scenario: ScaleBiasScenario, rng: np.random.Generator, n: int) -> ScaleBiasSamples:
    """Draw n realizations of the truth and of both sensors' logs (draw order in the module docstring)."""
    s, t = scenario.scenario, scenario.truth
    n_samples = s.n_samples
    time = s.sample_times()
    prior = scenario.truth_prior()
    theta0 = prior.mean + rng.standard_normal((n, 2)) @ _factor(prior.cov).T
    if s.drift == "random-walk":
        steps = rng.standard_normal((n, n_samples, 2)) * scenario.truth_drift_std
        theta = theta0[:, None, :] + np.cumsum(steps, axis=1)
    else:
        theta = np.broadcast_to(theta0[:, None, :], (n, n_samples, 2))
    eta = rng.standard_normal((n, n_samples))  # scaled in place: the same numbers, a block's array fewer
    eta *= t.reference_noise_std
    nu = rng.standard_normal((n, n_samples))
    nu *= t.sensor_noise_std
    profile = scenario.profile(time)
    if s.excitation == "sensor":
        clean = np.broadcast_to(profile, (n, n_samples))
        psi = theta[..., 0] * profile + theta[..., 1]
    else:
        psi = np.broadcast_to(profile, (n, n_samples))
        clean = (profile - theta[..., 1]) / theta[..., 0]
    # v = psi + eta and z = clean - nu, written over the noise (the same sums, no new arrays)
    return ScaleBiasSamples(time, theta, psi, clean, np.add(psi, eta, out=eta), np.subtract(clean, nu, out=nu))


def _factor(cov: np.ndarray) -> np.ndarray:
    """A square factor L with L L^T = cov (zero columns where the prior is degenerate)."""
    factor = psd_factor(cov)
    return np.pad(factor, ((0, 0), (0, cov.shape[0] - factor.shape[1])))
