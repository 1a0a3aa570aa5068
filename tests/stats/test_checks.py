"""The statistical checks: they pass a correct filter at their stated rate and catch the wrong ones."""

from functools import lru_cache

import numpy as np
import pytest
from scipy import stats

from kalcal.scenarios.accel_gps.settings import AccelGpsScenario
from kalcal.models.config import apply_settings
from kalcal.montecarlo.accumulators import ensemble_statistics
from kalcal.montecarlo.engine import run_monte_carlo
from kalcal.montecarlo.scenarios import build_problem
from kalcal.stats.bounds import chi2_mean_bounds, covariance_element_bound, normal_bound
from kalcal.stats.suite import run_checks, verdict


def _checks(n, seed=0, **settings):
    return dict(_cached_checks(n, seed, tuple(sorted(settings.items()))))


@lru_cache(maxsize=None)
def _cached_checks(n, seed, settings):
    """The same run is asked for by several tests: simulate it once (results are immutable)."""
    scenario = apply_settings(AccelGpsScenario(), dict(settings))
    problem, cause = build_problem(scenario)
    s = ensemble_statistics(run_monte_carlo(problem, n, seed).sums)
    return tuple((c.name, c) for c in run_checks(s, problem.info, 0.99, problem.expected_mean_error(), cause))


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
    assert mean.cause.explained_by == "model_error" and mean.cause.reason in mean.detail
    # the spread is right: the failure is the mean, reported once
    assert checks["covariance"].passed
    for name in ("orthogonality", "residual_whiteness", "nis"):
        if not checks[name].passed:
            assert checks[name].cause.explained_by == "mean_error", (name, checks[name].detail)
    assert not checks["residual_whiteness"].passed  # the Euler mean residuals are large enough at this N


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
    assert checks["covariance"].cause.direction == "overconfident"
    assert checks["covariance"].cause.explained_by is None


def test_overcautious_filter_fails_as_underconfident():
    checks = _checks(20000, seed=4, **{"scenario.truth": "discrete", "filter.gps_position_std": 3.0})
    assert not checks["covariance"].passed
    assert "underconfident" in checks["covariance"].detail
    assert checks["covariance"].cause.direction == "underconfident"
    assert not checks["nis"].passed and checks["nis"].statistic < checks["nis"].lower
    assert checks["nis"].cause.direction == "underconfident"


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
    assert biased.cause.explained_by == "mean_error" and biased.cause.direction is None
    mistuned = _checks(20000, seed=6, **{"scenario.truth": "discrete", "filter.gps_position_std": 0.5})["nis"]
    assert not mistuned.passed and mistuned.statistic > mistuned.upper
    assert "noise settings are too small" in mistuned.detail and "account for it" not in mistuned.detail
    assert mistuned.cause.explained_by is None and mistuned.cause.direction == "overconfident"


RUNS = {
    "passing": (20000, 1, {"scenario.truth": "discrete"}),
    "euler": (20000, 0, {}),
    "overconfident": (20000, 3, {"scenario.truth": "discrete", "filter.accel_noise_std": 0.002}),
    "underconfident": (20000, 4, {"scenario.truth": "discrete", "filter.gps_position_std": 3.0}),
}


@pytest.mark.parametrize("run", RUNS)
def test_pvalue_bounds_and_verdict_agree_for_every_check(run):
    """passed == (pvalue >= 1 - confidence); each test inside its own bounds exactly when it passes."""
    n, seed, settings = RUNS[run]
    checks = _checks(n, seed, **settings)
    for check in checks.values():
        alpha = 1 - check.confidence
        assert 0.0 <= check.pvalue <= 1.0
        assert check.passed == (check.pvalue >= alpha), check
        tests = check.parts or (check,)
        for test in tests:
            inside = (test.lower is None or test.statistic >= test.lower) and test.statistic <= test.upper
            assert inside == test.passed, (check.name, test)
        if check.parts:
            share = alpha / len(check.parts)
            assert all(part.alpha == share for part in check.parts)
            assert all(part.passed == (part.pvalue >= share) for part in check.parts)
            assert check.pvalue == pytest.approx(min(1.0, len(check.parts) * min(p.pvalue for p in check.parts)))
            assert check.passed == all(part.passed for part in check.parts)
            assert check.comparisons == sum(part.comparisons for part in check.parts)
            assert (check.statistic, check.upper) == (check.parts[0].statistic, check.parts[0].upper)
        else:
            # the Bonferroni p-value of the family's deciding comparison
            if check.lower is None:
                expected = min(1.0, check.comparisons * 2 * stats.norm.sf(check.statistic))
            else:
                x = check.statistic * 20000
                dof = 2 * 20000
                expected = min(1.0, check.comparisons * 2 * min(stats.chi2.cdf(x, dof), stats.chi2.sf(x, dof)))
            assert check.pvalue == pytest.approx(expected, rel=1e-9, abs=1e-300)
        if check.passed:
            assert check.cause == type(check.cause)()
    if run == "passing":
        assert all(c.passed for c in checks.values())
    else:
        assert not all(c.passed for c in checks.values())


def test_covariance_check_splits_its_alpha_between_its_two_parts():
    """Both parts are held at alpha / 2: the element bound is the normal quantile for 2 x the comparisons."""
    cov = _checks(20000, 1, **{"scenario.truth": "discrete"})["covariance"]
    elements, nees = cov.parts
    assert (elements.name, nees.name) == ("elements", "centered_nees")
    assert elements.upper == pytest.approx(normal_bound(0.99, 2 * elements.comparisons))
    assert elements.upper == covariance_element_bound(0.99, 150, 3)  # the band of the report's figures
    low, high = chi2_mean_bounds(0.995, nees.comparisons, 3 * (20000 - 1), 20000 - 1)
    assert (nees.lower, nees.upper) == (pytest.approx(low), pytest.approx(high))
    assert nees.comparisons == 150 and elements.comparisons == 150 * 6
