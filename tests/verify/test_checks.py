"""The statistical checks: they pass a correct filter at their stated rate and catch the wrong ones."""

import numpy as np
import pytest
from scipy import stats

from kalcal.models.accel_gps import AccelGpsScenario
from kalcal.models.config import apply_settings
from kalcal.montecarlo.accumulators import ensemble_statistics
from kalcal.montecarlo.engine import run_monte_carlo
from kalcal.montecarlo.scenarios import build_problem
from kalcal.verify.checks import chi2_mean_bounds, normal_bound, run_checks, verdict


def _checks(n, seed=0, **settings):
    scenario = apply_settings(AccelGpsScenario(), settings)
    problem, cause = build_problem(scenario)
    s = ensemble_statistics(run_monte_carlo(problem, n, seed).sums)
    return {c.name: c for c in run_checks(s, problem.info, 0.99, problem.expected_mean_error(), cause)}


def test_bounds_are_the_quantiles():
    assert normal_bound(0.95, 1) == pytest.approx(1.959964, abs=1e-6)
    # Bonferroni: alpha / m split over two tails
    assert normal_bound(0.99, 10) == pytest.approx(stats.norm.isf(0.0005))
    low, high = chi2_mean_bounds(0.99, 1, 2 * 1000, 1000)
    assert low == pytest.approx(stats.chi2.ppf(0.005, 2000) / 1000)
    assert high == pytest.approx(stats.chi2.isf(0.005, 2000) / 1000)


def test_report_default_flags_the_euler_mean_error_and_says_why():
    checks = _checks(20000)
    mean = checks["mean_error"]
    assert not mean.passed and mean.statistic > mean.upper
    assert "euler integration" in mean.detail and "Explained by the predicted systematic error" in mean.detail
    # the spread is right: the failure is the mean, reported once
    assert checks["covariance"].passed
    for name in ("orthogonality", "residual_whiteness"):
        if not checks[name].passed:
            assert "mean" in checks[name].detail


def test_discrete_truth_passes_everything():
    checks = _checks(20000, seed=1, **{"scenario.truth": "discrete"})
    assert verdict(list(checks.values())) == "pass", [c.detail for c in checks.values() if not c.passed]


def test_trapezoid_integration_clears_the_mean_error():
    checks = _checks(20000, seed=2, **{"scenario.integration": "trapezoid"})
    assert checks["mean_error"].passed
    assert checks["covariance"].passed


def test_mistuned_filter_fails_covariance():
    checks = _checks(20000, seed=3, **{"scenario.truth": "discrete", "filter.accel_noise_std": 0.002})
    assert not checks["covariance"].passed
    assert "overconfident" in checks["covariance"].detail


def test_overcautious_filter_fails_as_underconfident():
    checks = _checks(20000, seed=4, **{"scenario.truth": "discrete", "filter.gps_position_std": 3.0})
    assert not checks["covariance"].passed
    assert "underconfident" in checks["covariance"].detail
    assert not checks["nis"].passed and checks["nis"].statistic < checks["nis"].lower


def test_correct_model_passes_at_about_the_stated_rate():
    """80 independent small ensembles of a correct filter: each check may fail with probability <= 1%.

    The number of failures of each check is then stochastically below Binomial(80, 0.01), whose 99.9%
    quantile is 5 (``scipy.stats.binom.ppf(0.999, 80, 0.01)``; P(X > 5) = 1.6e-4, P(X > 4) = 1.3e-3).
    """
    runs = 80
    limit = stats.binom.ppf(0.999, runs, 0.01)
    failures = {}
    for seed in range(runs):
        for name, check in _checks(2000, seed=1000 + seed, **{"scenario.truth": "discrete", "scenario.duration": 2.0}).items():
            failures[name] = failures.get(name, 0) + (not check.passed)
    assert all(count <= limit for count in failures.values()), failures


def test_mean_error_z_scores_are_standard_normal_on_a_correct_model():
    """The building block of the checks: z = mean / se is N(0, 1); a KS test at 0.1% must not reject."""
    scenario = apply_settings(AccelGpsScenario(), {"scenario.truth": "discrete", "scenario.duration": 10.0})
    problem, _ = build_problem(scenario)
    s = ensemble_statistics(run_monte_carlo(problem, 4000, seed=99).sums)
    # one state per update time is nearly independent across well-separated updates: take every 5th
    z = (s.mean_error / np.sqrt(np.diagonal(s.error_cov, axis1=1, axis2=2) / s.count))[::5, 0]
    assert stats.kstest(z, "norm").pvalue > 0.001


def test_nis_failure_is_attributed_to_the_mean_residuals_or_to_the_noise():
    """The centered mean NIS (E|nu|^2 - |E nu|^2) separates a biased filter from a mistuned one."""
    biased = _checks(20000, seed=5)["nis"]  # Euler against the analytic truth: mean innovations
    assert not biased.passed and "nonzero mean residuals account for it" in biased.detail
    mistuned = _checks(20000, seed=6, **{"scenario.truth": "discrete", "filter.gps_position_std": 0.5})["nis"]
    assert not mistuned.passed and mistuned.statistic > mistuned.upper
    assert "noise settings are too small" in mistuned.detail and "account for it" not in mistuned.detail
