"""Simulate logs, calibrate, and hold the bias estimate to the filter's own uncertainty."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy import stats

from kalcal.scenarios.accel_gps.calibration import calibrate_accel_gps
from kalcal.core.steps import covariance_pass
from kalcal.errors import DataError
from kalcal.filters.gains import run_with_gains
from kalcal.scenarios.accel_gps.mechanization import integrate
from kalcal.scenarios import build_scenario
from kalcal.scenarios.accel_gps.sampled import sample_accel_gps_logs
from tests._helpers import assert_close, cov_atol


def _scenario(integration="euler", truth="analytic", *extra):
    return build_scenario(
        "accel-gps", assignments=[f"scenario.integration={integration}", f"scenario.truth={truth}", *extra]
    )


def _calibrate(scenario, logs, i=0, **kwargs):
    return calibrate_accel_gps(
        scenario, logs.sample_time, logs.accel[i], logs.fix_time, logs.gps_position[i], logs.gps_velocity[i], **kwargs
    )


@pytest.mark.parametrize("integration", ["euler", "trapezoid"])
def test_bias_recovered_within_four_sigma_over_seeds(integration):
    scenario = _scenario(integration, "analytic")
    for seed in range(8):
        logs = sample_accel_gps_logs(scenario, np.random.default_rng(seed), 1)
        result = _calibrate(scenario, logs)
        assert result.bias.shape == (150,)
        z = (result.bias[-1] - logs.bias[0, -1]) / result.std[-1, 2]
        assert abs(z) <= 4.0, f"seed {seed}: bias error {z:.2f} sigma"
        # The estimate is informative: its sigma is far below the prior's 0.1 m/s^2.
        assert result.std[-1, 2] < 0.01 * scenario.truth.bias_std


def test_covariance_equals_the_data_free_pass():
    scenario = _scenario()
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(1), 2)
    schedule = covariance_pass(scenario.filter_model(), scenario.scenario.n_updates)
    for i in range(2):
        result = _calibrate(scenario, logs, i)
        assert_close(result.covariance[-1], schedule.posterior_cov[-1], atol=cov_atol(schedule.posterior_cov[-1], 1e-12))
        assert_close(result.covariance, schedule.posterior_cov, atol=cov_atol(schedule.posterior_cov, 1e-12))
        np.testing.assert_allclose(result.innovation_cov, schedule.innovation_cov, rtol=1e-12)
        np.testing.assert_allclose(result.std, np.sqrt(np.diagonal(schedule.posterior_cov, axis1=1, axis2=2)), rtol=1e-12)


@pytest.mark.parametrize("integration", ["euler", "trapezoid"])
def test_estimates_equal_run_with_gains_on_error_measurements(integration):
    """Integrate the log by the scheme, form dz at the fixes, and run the precomputed-gain recursion."""
    scenario = _scenario(integration)
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(2), 1)
    result = _calibrate(scenario, logs)
    p_c, v_c = integrate(logs.accel[0], scenario.scenario.sample_period, *scenario.nominal_start(), integration)
    fix = logs.fix_index
    dz = np.stack([logs.gps_position[0] - p_c[fix], logs.gps_velocity[0] - v_c[fix]], axis=-1)
    model = scenario.filter_model()
    run = run_with_gains(covariance_pass(model, fix.size), model.h, dz[None], model.x0)
    sigma = result.std
    assert_close(result.error_state, run.posterior[0], rtol=1e-9, atol=1e-9 * sigma, what="error state")
    assert_close(result.residual, run.residual[0], rtol=1e-9, atol=1e-9 * sigma[:, :2], what="residual")
    np.testing.assert_allclose(result.position, p_c[fix] + run.posterior[0, :, 0], rtol=1e-12)
    np.testing.assert_allclose(result.velocity, v_c[fix] + run.posterior[0, :, 1], rtol=1e-12)
    np.testing.assert_array_equal(result.bias, result.error_state[:, 2])
    np.testing.assert_allclose(result.time, logs.fix_time, rtol=0, atol=0)


def test_normalized_bias_errors_are_standard_normal_without_model_error():
    """Euler against the discrete truth: the filter's model is exact, so (b_hat - b) / sigma ~ N(0, 1)."""
    scenario = _scenario("euler", "discrete")
    n_seeds = 40
    z = np.empty(n_seeds)
    for seed in range(n_seeds):
        logs = sample_accel_gps_logs(scenario, np.random.default_rng(1000 + seed), 1)
        result = _calibrate(scenario, logs)
        z[seed] = (result.bias[-1] - logs.bias[0, -1]) / result.std[-1, 2]
    assert abs(z.mean()) <= 3 / np.sqrt(n_seeds), f"mean {z.mean():.3f}"
    low = stats.chi2.ppf(0.0005, n_seeds - 1) / (n_seeds - 1)
    high = stats.chi2.isf(0.0005, n_seeds - 1) / (n_seeds - 1)
    assert low <= z.var(ddof=1) <= high, f"variance {z.var(ddof=1):.3f} outside [{low:.3f}, {high:.3f}]"


def test_sparser_fixes_follow_the_pass_of_the_longer_interval():
    """Using every other fix is the same filter with 80 samples per update."""
    scenario = _scenario()
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(3), 1)
    keep = slice(1, None, 2)
    result = calibrate_accel_gps(
        scenario,
        logs.sample_time,
        logs.accel[0],
        logs.fix_time[keep],
        logs.gps_position[0, keep],
        logs.gps_velocity[0, keep],
    )
    model = dataclasses.replace(scenario.filter_model(), steps_per_update=80)
    schedule = covariance_pass(model, 75)
    assert_close(result.covariance, schedule.posterior_cov, atol=cov_atol(schedule.posterior_cov, 1e-11))


def test_fix_at_time_zero_is_an_update_without_propagation():
    scenario = _scenario()
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(4), 1)
    model = scenario.filter_model()
    fixes = np.array([0, logs.fix_index[0]])
    result = calibrate_accel_gps(
        scenario, logs.sample_time, logs.accel[0], logs.sample_time[fixes], logs.position[0, fixes], logs.velocity[0, fixes]
    )
    # One update of the prior M0 with V: diagonal, so each measured state combines two variances.
    m0, v = np.diag(model.m0), np.diag(model.v)
    expected = np.array([m0[0] * v[0] / (m0[0] + v[0]), m0[1] * v[1] / (m0[1] + v[1]), m0[2]])
    np.testing.assert_allclose(np.diag(result.covariance[0]), expected, rtol=1e-12)


def test_log_starting_later_gives_the_same_estimates():
    scenario = _scenario()
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(5), 1)
    base = _calibrate(scenario, logs)
    shifted = calibrate_accel_gps(
        scenario,
        logs.sample_time + 100.0,
        logs.accel[0],
        logs.fix_time + 100.0,
        logs.gps_position[0],
        logs.gps_velocity[0],
    )
    # Time stamps near 100 s carry eps * 100 s of rounding, so the sample period is known to ~1e-12
    # relative; over ~6000 m of travel that moves p_c by ~1e-8 m, a few 1e-7 of the position sigma.
    sigma = base.std
    assert_close(shifted.error_state, base.error_state, rtol=1e-9, atol=1e-6 * sigma)
    assert_close(shifted.covariance, base.covariance, atol=cov_atol(base.covariance, 1e-9))


@pytest.mark.parametrize(
    "gps_time, pattern",
    [
        (np.array([0.2, 30.2]), r"gps\.csv: needs at least two usable fixes .*1 outside the log"),
        (np.array([-0.2, 0.2]), r"gps\.csv: needs at least two usable fixes .*1 outside the log"),
        (np.array([30.2, 30.4]), r"gps\.csv: no fix lies within the accelerometer log"),
    ],
)
def test_too_few_fixes_inside_the_log_raise_data_error(gps_time, pattern):
    scenario = _scenario()
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(6), 1)
    with pytest.raises(DataError, match=pattern):
        calibrate_accel_gps(
            scenario, logs.sample_time, logs.accel[0], gps_time, np.zeros(2), np.zeros(2), source="gps.csv"
        )


def test_fixes_outside_the_log_are_skipped_and_counted():
    scenario = _scenario()
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(6), 1)
    times = np.concatenate([[-0.2], logs.fix_time, [30.2]])
    position = np.concatenate([[0.0], logs.gps_position[0], [0.0]])
    velocity = np.concatenate([[0.0], logs.gps_velocity[0], [0.0]])
    result = calibrate_accel_gps(scenario, logs.sample_time, logs.accel[0], times, position, velocity)
    inside = _calibrate(scenario, logs)
    assert result.skipped_outside == 2 and result.time.size == logs.fix_time.size
    np.testing.assert_array_equal(result.error_state, inside.error_state)


def test_uneven_accelerometer_spacing_uses_each_step():
    """A shifted clock for part of the log is integrated step by step: no gap, and the process noise of the
    longer step enters the covariance."""
    scenario = _scenario()
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(7), 1)
    time = logs.sample_time.copy()
    time[100:] += 0.001
    fixes = time[logs.fix_index]
    result = calibrate_accel_gps(scenario, time, logs.accel[0], fixes, logs.gps_position[0], logs.gps_velocity[0])
    assert not result.gaps and np.all(np.isfinite(result.error_state))


# --------------------------------------------------------------------------------------------------
# regressions of bugs found when this suite was written


def test_fixes_on_samples_of_a_log_stamped_in_gps_time_of_week_are_accepted():
    """The same 30 s log, time-stamped from Wednesday 00:00 GPS time (t0 = 345600 s)."""
    scenario = _scenario()
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(5), 1)
    t0 = 345600.0
    fix_time = logs.sample_time[logs.fix_index] + t0
    imu_time = logs.sample_time + t0
    assert np.all(np.isin(fix_time, imu_time))  # every fix is bit-identical to a sample time
    shifted = calibrate_accel_gps(
        scenario, imu_time, logs.accel[0], fix_time, logs.gps_position[0], logs.gps_velocity[0]
    )
    base = _calibrate(scenario, logs)
    assert_close(shifted.covariance, base.covariance, atol=cov_atol(base.covariance, 1e-6))


@pytest.mark.parametrize("late", [1e6, 1e300])
def test_fix_far_outside_the_log_is_reported_as_outside(late):
    scenario = _scenario()
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(6), 1)
    with pytest.raises(DataError, match=r"1 outside the log"):
        calibrate_accel_gps(
            scenario, logs.sample_time, logs.accel[0], np.array([0.2, late]), np.zeros(2), np.zeros(2), source="gps.csv"
        )


def test_out_of_order_fixes_are_rejected():
    scenario = _scenario()
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(7), 1)
    order = np.array([0, 2, 1, 3])
    with pytest.raises(DataError, match="row 3"):
        calibrate_accel_gps(
            scenario,
            logs.sample_time,
            logs.accel[0],
            logs.fix_time[order],
            logs.gps_position[0, order],
            logs.gps_velocity[0, order],
        )
