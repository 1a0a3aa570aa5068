"""Per-sample sensor streams: the logs and the streamed error states are the same realizations."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from kalcal.scenarios.accel_gps.mechanization import integrate
from kalcal.scenarios import build_scenario
from kalcal.scenarios.accel_gps.sampled import sample_accel_gps_errors, sample_accel_gps_logs


def _scenario(integration="euler", truth="analytic", *extra):
    return build_scenario(
        "accel-gps", assignments=[f"scenario.integration={integration}", f"scenario.truth={truth}", *extra]
    )


@pytest.mark.parametrize("truth", ["analytic", "discrete"])
@pytest.mark.parametrize("integration", ["euler", "trapezoid"])
def test_logs_and_streamed_errors_are_the_same_realizations(integration, truth):
    scenario = _scenario(integration, truth)
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(7), 3)
    states, measurements = sample_accel_gps_errors(scenario, np.random.default_rng(7), 3)
    assert states.shape == (3, 150, 3) and measurements.shape == (3, 150, 2)
    # Integrate the logged accelerometer as a user would, from the filter's prior means.
    p_c, v_c = integrate(logs.accel, scenario.scenario.sample_period, *scenario.nominal_start(), integration)
    fix = logs.fix_index
    np.testing.assert_allclose(states[:, :, 0], logs.position[:, fix] - p_c[:, fix], rtol=0, atol=1e-9)
    np.testing.assert_allclose(states[:, :, 1], logs.velocity[:, fix] - v_c[:, fix], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(states[:, :, 2], logs.bias[:, logs.fix_index])
    np.testing.assert_allclose(measurements[:, :, 0], logs.gps_position - p_c[:, fix], rtol=0, atol=1e-9)
    np.testing.assert_allclose(measurements[:, :, 1], logs.gps_velocity - v_c[:, fix], rtol=0, atol=1e-9)


def test_logs_shapes_and_times():
    scenario = _scenario()
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(1), 2)
    assert logs.accel.shape == logs.position.shape == logs.velocity.shape == (2, 6001)
    assert logs.sample_time.shape == logs.true_accel.shape == (6001,)
    assert logs.gps_position.shape == logs.gps_velocity.shape == (2, 150)
    np.testing.assert_array_equal(logs.fix_index, np.arange(1, 151) * 40)
    np.testing.assert_allclose(logs.fix_time, scenario.scenario.update_times(), rtol=1e-12)
    assert logs.fix_time[0] == pytest.approx(0.2, rel=1e-12)


def test_same_seed_same_logs_and_different_seed_different_logs():
    scenario = _scenario()
    a = sample_accel_gps_logs(scenario, np.random.default_rng(3), 2)
    b = sample_accel_gps_logs(scenario, np.random.default_rng(3), 2)
    c = sample_accel_gps_logs(scenario, np.random.default_rng(4), 2)
    np.testing.assert_array_equal(a.accel, b.accel)
    np.testing.assert_array_equal(a.gps_position, b.gps_position)
    assert not np.any(a.accel == c.accel)


def test_analytic_truth_follows_the_closed_form():
    scenario = _scenario()
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(5), 2)
    t = logs.sample_time
    p0, v0 = logs.position[:, :1], logs.velocity[:, :1]
    # The report's p(t) = p0 + (v0 + A/w) t - A/w^2 sin(w t), v(t) = v0 + A/w - A/w cos(w t).
    np.testing.assert_allclose(logs.velocity, v0 + 100 - 100 * np.cos(0.1 * t), rtol=1e-12, atol=1e-10)
    np.testing.assert_allclose(logs.position, p0 + (v0 + 100) * t - 1000 * np.sin(0.1 * t), rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(logs.true_accel, 10 * np.sin(0.1 * t), rtol=1e-15)


@pytest.mark.parametrize("integration", ["euler", "trapezoid"])
def test_discrete_truth_is_the_scheme_applied_to_the_true_samples(integration):
    scenario = _scenario(integration, "discrete")
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(6), 2)
    position, velocity = integrate(
        logs.true_accel, scenario.scenario.sample_period, logs.position[:, 0], logs.velocity[:, 0], integration
    )
    np.testing.assert_allclose(logs.position, position, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(logs.velocity, velocity, rtol=1e-12, atol=1e-10)


def _chi2_variance_bounds(dof: int, alpha: float = 1e-4) -> tuple[float, float]:
    """Bounds on s^2 / sigma^2 for a sample variance with ``dof`` degrees of freedom."""
    return stats.chi2.ppf(alpha / 2, dof) / dof, stats.chi2.isf(alpha / 2, dof) / dof


def test_logged_noise_has_the_configured_statistics():
    """accel - a - b, GPS - truth, and the initial draws have the truth's standard deviations."""
    scenario = _scenario()
    t = scenario.truth
    n = 400
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(8), n)
    fix = logs.fix_index
    checks = {
        "accel": (logs.accel - logs.true_accel - logs.bias, t.accel_noise_std),
        "gps_position": (logs.gps_position - logs.position[:, fix], t.gps_position_std),
        "gps_velocity": (logs.gps_velocity - logs.velocity[:, fix], t.gps_velocity_std),
        "bias": (logs.bias[:, 0], t.bias_std),
        "position0": (logs.position[:, 0] - t.position0_mean, t.position0_std),
        "velocity0": (logs.velocity[:, 0] - t.velocity0_mean, t.velocity0_std),
    }
    for name, (values, sigma) in checks.items():
        values = values.ravel()
        # Known mean zero: sum of squares / sigma^2 is chi-square with N degrees of freedom.
        ratio = np.mean(values**2) / sigma**2
        low, high = _chi2_variance_bounds(values.size)
        assert low <= ratio <= high, f"{name}: variance ratio {ratio:.4f} outside [{low:.4f}, {high:.4f}]"
        k = stats.norm.isf(1e-4 / 2)
        assert abs(values.mean()) <= k * sigma / np.sqrt(values.size), name


def test_streamed_errors_do_not_depend_on_how_they_are_read_back():
    """Two calls with equal generators give identical arrays (randomness only from the generator)."""
    scenario = _scenario("trapezoid", "analytic", "scenario.duration=2")
    a = sample_accel_gps_errors(scenario, np.random.default_rng(9), 5)
    b = sample_accel_gps_errors(scenario, np.random.default_rng(9), 5)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
