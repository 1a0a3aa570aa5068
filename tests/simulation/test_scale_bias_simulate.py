"""Realizations of the scale/bias scenario: the note's sensor equations, the prior, the drift."""

from __future__ import annotations

import numpy as np
import pytest

from kalcal.scenarios import build_scenario
from kalcal.scenarios.scale_bias.theta import scale_bias_from_theta
from kalcal.scenarios.scale_bias.simulation import normals_per_realization, sample_scale_bias
from tests._helpers import assert_gaussian_moments


@pytest.mark.parametrize("excitation", ["sensor", "reference"])
def test_logs_follow_the_notes_equations(excitation):
    scenario = build_scenario("scale-bias", assignments=[f"scenario.excitation={excitation}"])
    samples = sample_scale_bias(scenario, np.random.default_rng(1), 3)
    a, b = scale_bias_from_theta(samples.theta)
    profile = scenario.profile(samples.time)
    # zeta = (1 - a) psi - b (eq. 2 without noise); the profile drives zeta or psi.
    np.testing.assert_allclose(samples.clean_sensor, (1 - a) * samples.psi - b, rtol=1e-12, atol=1e-12)
    driven = samples.clean_sensor if excitation == "sensor" else samples.psi
    np.testing.assert_allclose(driven, np.broadcast_to(profile, driven.shape), rtol=1e-12, atol=1e-12)
    # v = theta1 z + theta2 + w with w = eta + theta1 nu (eq. 5 with the exact noise)
    w = samples.reference - samples.theta[..., 0] * samples.sensor - samples.theta[..., 1]
    eta = samples.reference - samples.psi
    nu = samples.clean_sensor - samples.sensor
    np.testing.assert_allclose(w, eta + samples.theta[..., 0] * nu, rtol=0, atol=1e-12)
    assert samples.theta.shape == (3, 300, 2) and samples.reference.shape == (3, 300)
    # constant parameters without drift
    np.testing.assert_array_equal(samples.theta, np.broadcast_to(samples.theta[:, :1], samples.theta.shape))


def test_prior_noise_and_drift_have_their_distributions():
    scenario = build_scenario("scale-bias", assignments=["scenario.drift=random-walk", "scenario.duration=5"])
    n = 20_000
    samples = sample_scale_bias(scenario, np.random.default_rng(2), n)
    prior = scenario.truth_prior()
    q = scenario.truth.parameter_drift_std
    k = samples.time.size
    # theta at sample k = theta_0 + k increments: N(mean, P0 + k q^2 I)
    assert_gaussian_moments(samples.theta[:, 0], prior.mean, prior.cov + q**2 * np.eye(2), what="theta_1")
    assert_gaussian_moments(samples.theta[:, -1], prior.mean, prior.cov + k * q**2 * np.eye(2), what="theta_K")
    steps = np.diff(samples.theta, axis=1).reshape(-1, 2)[:n]
    assert_gaussian_moments(steps, np.zeros(2), q**2 * np.eye(2), what="increments")
    t = scenario.truth
    noise = np.column_stack(
        [(samples.reference - samples.psi)[:, 7], (samples.clean_sensor - samples.sensor)[:, 7]]
    )
    assert_gaussian_moments(noise, np.zeros(2), np.diag([t.reference_noise_std**2, t.sensor_noise_std**2]), what="noise")


def test_same_generator_same_realizations_and_a_known_bias():
    scenario = build_scenario("scale-bias")
    one = sample_scale_bias(scenario, np.random.default_rng(9), 4)
    two = sample_scale_bias(scenario, np.random.default_rng(9), 4)
    np.testing.assert_array_equal(one.reference, two.reference)
    np.testing.assert_array_equal(one.sensor, two.sensor)
    known = build_scenario("scale-bias", assignments=["truth.bias_std=0", "filter.bias_std=0.1"])
    _, b = scale_bias_from_theta(sample_scale_bias(known, np.random.default_rng(9), 50).theta)
    np.testing.assert_allclose(b, 0.05, rtol=1e-12)


def test_normals_per_realization():
    assert normals_per_realization(build_scenario("scale-bias")) == 2 + 2 * 300
    assert normals_per_realization(build_scenario("scale-bias", assignments=["scenario.drift=random-walk"])) == 2 + 4 * 300
