"""Stability across a log: windows of a constant log agree at the test's rate, a step or a drift is flagged.

Bounds from theory: over M independent logs the count of p-values below the level is binomial(M, level)
and the sum of the statistics is chi-square(M dof); both are held to 1e-3 (two-sided where the test is
exact, one-sided where it is documented as conservative).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from kalcal.scenarios.accel_gps.calibration import calibrate_accel_gps
from kalcal.scenarios.scale_bias.calibration import calibrate_scale_bias
from kalcal.calibration.stability import LEVEL, difference_statistic, time_windows, weighted_mean_statistic
from kalcal.calibration.windows import check_windows
from kalcal.scenarios.accel_gps.windows import accel_gps_stability
from kalcal.scenarios.scale_bias.windows import scale_bias_stability
from kalcal.errors import ConfigError
from kalcal.scenarios.accel_gps.settings import AccelGpsScenario
from kalcal.models.config import apply_settings
from kalcal.scenarios.scale_bias.settings import ScaleBiasScenario
from kalcal.scenarios.accel_gps.sampled import sample_accel_gps_logs
from kalcal.scenarios.scale_bias.simulation import sample_scale_bias

LOGS = 40
EXACT = {"scenario.truth": "discrete", "scenario.integration": "trapezoid"}


def _accel_gps(settings: dict, seed: int, n: int = LOGS):
    scenario = apply_settings(AccelGpsScenario(), {**EXACT, **settings})
    return scenario, sample_accel_gps_logs(scenario, np.random.default_rng(seed), n)


def _stability(scenario, logs, i: int, windows: int = 2, accel=None):
    args = (logs.sample_time, logs.accel[i] if accel is None else accel, logs.fix_time,
            logs.gps_position[i], logs.gps_velocity[i])  # fmt: skip
    whole = calibrate_accel_gps(scenario, *args, init="first-fix")
    return accel_gps_stability(scenario, whole, *args, windows)


def _bounds(results, exact: bool):
    """Assert the false-alarm count and the summed statistic of ``results`` against their laws: upper
    bounds, and with ``exact`` the chi-square's lower bound too. A drifting model's test is conservative
    (its C leaves out the windows' errors' correlation with the drift, kalcal.calibration.stability):
    its statistic is stochastically smaller than chi-square by an amount the theory does not bound, so
    it has no lower bound to hold."""
    count = sum(r.p_value < LEVEL for r in results)
    total, dof = sum(r.statistic for r in results), sum(r.dof for r in results)
    assert count <= stats.binom.ppf(0.999, len(results), LEVEL)
    assert total <= stats.chi2.ppf(0.999, dof)
    if exact:
        assert total >= stats.chi2.ppf(0.001, dof)


def test_the_weighted_mean_form_is_the_stacked_differences_with_no_drift():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(4, 2))
    roots = rng.normal(size=(4, 2, 2))
    p = roots @ roots.transpose(0, 2, 1) + 0.1 * np.eye(2)
    assert difference_statistic(x, p) == pytest.approx(weighted_mean_statistic(x, p), rel=1e-10)


def test_a_drift_covariance_and_decay_enter_the_differences():
    x, p = np.array([[1.0], [0.5]]), np.array([[[0.1]], [[0.2]]])
    # d = 0.5 - 0.5 * 1 = 0 with Phi = 0.5; with Phi = 1 and Q = 0.7: 0.25 / (0.1 + 0.2 + 0.7)
    assert difference_statistic(x, p, np.array([[[0.5]]]), np.array([[[0.3]]])) == 0.0
    assert difference_statistic(x, p, None, np.array([[[0.7]]])) == pytest.approx(0.25)


def test_time_windows_cover_every_time_once():
    times = np.linspace(0.0, 10.0, 101)
    parts = time_windows(times, 3, 0.0, 10.0)
    assert np.array_equal(np.concatenate(parts), np.arange(101))
    assert [round(times[p[-1]], 6) for p in parts] == [3.3, 6.6, 10.0]


@pytest.mark.parametrize("windows", [2, 3])
def test_a_constant_bias_is_stable_at_the_tests_rate(windows):
    scenario, logs = _accel_gps({}, 12 + windows)
    results = [_stability(scenario, logs, i, windows) for i in range(LOGS)]
    assert all(r.model == "constant" and r.dof == windows - 1 and len(r.windows) == windows for r in results)
    _bounds(results, exact=True)


def test_a_bias_that_steps_halfway_is_flagged_unstable():
    scenario, logs = _accel_gps({}, 7, n=1)
    steady = _stability(scenario, logs, 0)
    stepped = logs.accel[0] + np.where(logs.sample_time > 15.0, 0.02, 0.0)  # ~12 sigma of the difference
    result = _stability(scenario, logs, 0, accel=stepped)
    assert steady.stable and not result.stable and result.p_value < 1e-6
    assert result.sentence.startswith("NOT stable") and "bias" in result.sentence
    first, second = result.windows
    assert second.estimate[0] - first.estimate[0] == pytest.approx(0.02, abs=5 * np.hypot(first.std[0], second.std[0]))


def test_windows_start_from_their_own_first_fix_with_a_diffuse_bias():
    scenario, logs = _accel_gps({"filter.bias_std": 1e-4}, 3, n=1)  # a prior that would pin the bias
    result = _stability(scenario, logs, 0)
    first, second = result.windows
    assert first.start == pytest.approx(logs.fix_time[0]) and second.start > first.end
    # the windows' sigmas are their data's, far above the 1e-4 prior a window would otherwise keep
    assert first.std[0] > 5e-4 and "diffuse" in result.prior


def test_a_random_walk_model_is_tested_against_its_drift_conservatively():
    scenario, logs = _accel_gps({"truth.bias_walk_std": 1e-4}, 21)
    results = [_stability(scenario, logs, i, 3) for i in range(LOGS)]
    assert all(r.model == "random walk" for r in results)
    _bounds(results, exact=False)
    assert "random walk drift" in results[0].sentence


def test_a_walking_bias_is_unstable_under_a_constant_model_and_stable_under_its_own():
    scenario, logs = _accel_gps({"truth.bias_walk_std": 2e-3}, 5, n=1)
    constant = apply_settings(scenario, {"filter.bias_walk_std": 0.0})
    assert not _stability(constant, logs, 0).stable
    assert _stability(scenario, logs, 0).stable


def test_a_gauss_markov_bias_keeps_its_stationary_prior_and_its_decay():
    scenario, logs = _accel_gps({"truth.bias_correlation_time": 10.0}, 4, n=1)
    result = _stability(scenario, logs, 0, 3)
    assert result.model == "Gauss-Markov" and "stationary std" in result.prior
    assert result.statistic is not None and "Gauss-Markov drift" in result.sentence


def test_one_window_or_too_few_fixes_leave_the_test_not_run():
    scenario, logs = _accel_gps({"scenario.duration": 1.0}, 1, n=1)
    assert _stability(scenario, logs, 0, 1).sentence == "not tested: one window (--windows 1)"
    short = _stability(scenario, logs, 0, 3)  # 5 fixes: windows of one or two
    assert short.stable is None and short.statistic is None and "fewer than 3" in short.sentence


@pytest.mark.parametrize("bad", [0, -1, 2.5, True, "2"])
def test_windows_must_be_a_whole_number(bad):
    with pytest.raises(ConfigError, match="--windows: expected a whole number"):
        check_windows(bad)


def _scale_bias(settings: dict, seed: int, n: int = LOGS):
    scenario = apply_settings(ScaleBiasScenario(), {"scenario.duration": 6.0, **settings})
    return scenario, sample_scale_bias(scenario, np.random.default_rng(seed), n)


def _scale_bias_stability(scenario, samples, i: int, windows: int = 2, reference=None):
    reference = samples.reference[i] if reference is None else reference
    whole = calibrate_scale_bias(scenario, samples.time, reference, samples.sensor[i])
    return scale_bias_stability(scenario, whole, samples.time, reference, samples.sensor[i], windows)


def test_scale_bias_with_q_zero_is_stable_at_the_tests_rate():
    scenario, samples = _scale_bias({}, 30)
    results = [_scale_bias_stability(scenario, samples, i) for i in range(LOGS)]
    assert all(r.model == "constant" and r.dof == 2 and r.names == ("theta1", "theta2") for r in results)
    _bounds(results, exact=True)


def test_scale_bias_with_a_bias_step_is_unstable():
    scenario, samples = _scale_bias({}, 31, n=1)
    # the reference reads 0.6 (3 sigma_eta) more from halfway: theta2 steps by 0.6
    stepped = samples.reference[0] + np.where(np.arange(samples.time.size) >= samples.time.size // 2, 0.6, 0.0)
    assert _scale_bias_stability(scenario, samples, 0).stable
    result = _scale_bias_stability(scenario, samples, 0, reference=stepped)
    assert not result.stable and result.p_value < 1e-6


def test_scale_bias_with_a_drifting_filter_allows_the_walk():
    scenario, samples = _scale_bias({"scenario.drift": "random-walk", "filter.parameter_drift_std": "same"}, 32)
    results = [_scale_bias_stability(scenario, samples, i) for i in range(LOGS)]
    assert all(r.model == "random walk" for r in results)
    _bounds(results, exact=False)
