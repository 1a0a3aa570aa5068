"""The accelerometer/GPS scenario against the numbers of the source report (seed 000)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad

from kalcal.errors import ConfigError
from kalcal.scenarios.accel_gps.settings import AccelGpsScenario, AccelGpsSettings
from kalcal.scenarios import build_scenario


def test_filter_model_is_the_reports_model():
    model = AccelGpsScenario().filter_model()
    dt = 1 / 200
    np.testing.assert_allclose(model.phi, [[1, dt, -dt**2 / 2], [0, 1, -dt], [0, 0, 1]], rtol=1e-15)
    np.testing.assert_allclose(model.gamma, [[dt**2 / 2], [dt], [0]], rtol=1e-15)
    np.testing.assert_array_equal(model.h, [[1, 0, 0], [0, 1, 0]])
    np.testing.assert_allclose(model.w, [[0.0004]], rtol=1e-12)
    np.testing.assert_allclose(model.v, np.diag([1.0, 0.0016]), rtol=1e-12)
    np.testing.assert_allclose(model.m0, np.diag([100.0, 1.0, 0.01]), rtol=1e-12)
    np.testing.assert_array_equal(model.x0, np.zeros(3))
    assert model.steps_per_update == 40
    assert model.sample_period == pytest.approx(dt, rel=1e-15)
    assert model.update_period == pytest.approx(0.2, rel=1e-12)


def test_timing_of_the_report():
    s = AccelGpsSettings()
    assert (s.steps_per_update, s.n_updates, s.n_samples) == (40, 150, 6000)
    times = s.update_times()
    assert times.shape == (150,)
    assert times[0] == pytest.approx(0.2, rel=1e-12) and times[-1] == pytest.approx(30.0, rel=1e-12)
    np.testing.assert_allclose(np.diff(times), 0.2, rtol=1e-9)
    samples = s.sample_times()
    assert samples.shape == (6001,) and samples[0] == 0.0 and samples[-1] == pytest.approx(30.0, rel=1e-12)
    # Fixes lie on accelerometer samples.
    np.testing.assert_array_equal(samples[np.arange(1, 151) * 40], times)


def test_truth_model_prior_mean_is_the_offset_of_the_means():
    scenario = build_scenario(
        "accel-gps", assignments=["truth.position0_mean=5", "truth.velocity0_mean=97", "filter.velocity0_mean=100"]
    )
    # filter.position0_mean is unset, so it follows the truth's 5 m: no position offset.
    np.testing.assert_allclose(scenario.truth_model().x0, [0.0, -3.0, 0.0])
    np.testing.assert_array_equal(scenario.filter_model().x0, np.zeros(3))
    assert scenario.nominal_start() == (5.0, 100.0)
    # Same means everywhere: the truth's error state starts at zero mean too.
    np.testing.assert_array_equal(AccelGpsScenario().truth_model().x0, np.zeros(3))
    np.testing.assert_array_equal(AccelGpsScenario().truth_model().m0, AccelGpsScenario().filter_model().m0)


def test_true_accel_is_the_reports_profile():
    scenario = AccelGpsScenario()
    t = np.linspace(0, 30, 7)
    np.testing.assert_allclose(scenario.true_accel(t), 10 * np.sin(0.1 * t), rtol=1e-15)


@pytest.mark.parametrize("t", [0.0, 0.2, 7.3, 15.0, 30.0])
def test_analytic_motion_integrates_the_acceleration(t):
    """v(t) = int_0^t a, p(t) = int_0^t v, by adaptive quadrature (an independent oracle)."""
    scenario = AccelGpsScenario()
    position, velocity = scenario.analytic_motion(np.array([t]))

    def v(s):
        return quad(lambda u: float(scenario.true_accel(u)), 0.0, s, epsabs=1e-13, epsrel=1e-13)[0]

    assert velocity[0] == pytest.approx(v(t), rel=1e-9, abs=1e-11)
    assert position[0] == pytest.approx(quad(v, 0.0, t, epsabs=1e-12, epsrel=1e-12)[0], rel=1e-8, abs=1e-10)


def test_analytic_motion_matches_the_reports_closed_form():
    """The report's v(t) - v0 = 10/w (1 - cos wt), p(t) - p0 - v0 t = 10/w t - 10/w^2 sin wt."""
    t = np.linspace(0, 30, 151)
    position, velocity = AccelGpsScenario().analytic_motion(t)
    np.testing.assert_allclose(velocity, 100 * (1 - np.cos(0.1 * t)), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(position, 100 * t - 1000 * np.sin(0.1 * t), rtol=1e-9, atol=1e-9)


def test_zero_frequency_means_no_motion():
    scenario = build_scenario("accel-gps", assignments=["truth.accel_frequency=0"])
    position, velocity = scenario.analytic_motion(np.array([0.0, 1.0, 30.0]))
    np.testing.assert_array_equal(position, 0.0)
    np.testing.assert_array_equal(velocity, 0.0)
    np.testing.assert_array_equal(scenario.true_accel(np.array([1.0, 2.0])), 0.0)


@pytest.mark.parametrize(
    "kwargs, pattern",
    [
        (dict(imu_rate=200.0, gps_rate=3.0), r"scenario\.gps_rate"),
        (dict(gps_rate=400.0), r"scenario\.gps_rate"),  # fewer than one sample per fix
        (dict(duration=30.1), r"scenario\.duration"),
        (dict(duration=0.1), r"scenario\.duration"),  # shorter than one GPS interval
        (dict(duration=0.0), r"scenario\.duration"),
        (dict(imu_rate=-200.0), r"scenario\.imu_rate"),
    ],
)
def test_settings_validation(kwargs, pattern):
    with pytest.raises(ConfigError, match=pattern):
        AccelGpsSettings(**kwargs)


def test_non_default_timing():
    s = AccelGpsSettings(duration=12.0, imu_rate=100.0, gps_rate=4.0)
    assert (s.steps_per_update, s.n_updates, s.n_samples) == (25, 48, 1200)
    assert s.sample_period == pytest.approx(0.01, rel=1e-15)
    np.testing.assert_allclose(s.update_times()[:2], [0.25, 0.5], rtol=1e-12)
