"""The innovation diagnostics of ``calibrate``: NIS and Ljung-Box at half the alpha each, with p-values."""

import numpy as np
import pytest
from scipy import stats
from statsmodels.stats.diagnostic import acorr_ljungbox

from kalcal.calibration.diagnostics import CONSISTENT, innovation_diagnostics


def _ar1(rng, n, phi):
    x = np.empty(n)
    x[0] = rng.standard_normal()
    for k in range(1, n):
        x[k] = phi * x[k - 1] + np.sqrt(1 - phi**2) * rng.standard_normal()
    return x


def test_white_innovations_are_called_inconsistent_at_most_at_the_stated_rate():
    """600 logs of K = 1000 white N(0, I) innovations at 90% confidence.

    NIS OR Ljung-Box, each at the full alpha, called 106 of them inconsistent (60 now). With alpha split,
    the NIS part is exact at alpha / 2 and the Ljung-Box part (simulated null) at most at it, so the count
    stays below the 99.9% quantile of Binomial(600, 0.1), 84.
    """
    runs, confidence = 600, 0.9
    rng = np.random.default_rng(11)
    failures = sum(
        not innovation_diagnostics(rng.standard_normal((1000, 2)), confidence=confidence).consistent for _ in range(runs)
    )
    limit = stats.binom.ppf(0.999, runs, 1 - confidence)
    assert limit == 84
    assert failures <= limit


CASES = {
    "white": lambda rng: rng.standard_normal((400, 2)),
    "too_large": lambda rng: 1.3 * rng.standard_normal((400, 2)),
    "too_small": lambda rng: 0.7 * rng.standard_normal((400, 2)),
    "correlated": lambda rng: np.column_stack([_ar1(rng, 400, 0.5), rng.standard_normal(400)]),
}


@pytest.mark.parametrize("case", CASES)
def test_pvalue_bounds_parts_and_cause_agree(case):
    d = innovation_diagnostics(CASES[case](np.random.default_rng(5)), confidence=0.99)
    assert d.consistent == (d.pvalue >= 0.01)
    size, whiteness = d.parts
    assert (size.name, whiteness.name) == ("nis", "ljung_box")
    assert size.alpha == whiteness.alpha == pytest.approx(0.005)
    assert d.pvalue == pytest.approx(min(1.0, 2 * min(size.pvalue, whiteness.pvalue)))
    assert d.consistent == (size.passed and whiteness.passed)
    # every bound is in the result, and each part passes exactly when its statistics lie inside
    assert (size.lower, size.upper) == (d.nis_lower, d.nis_upper)
    assert size.passed == (d.nis_lower <= d.mean_nis <= d.nis_upper)
    # the bound is the simulated null's, whose tail at K = 400 is heavier than the asymptotic chi-square's
    assert whiteness.upper == d.ljung_box_upper > stats.chi2.isf(0.005 / 2, d.ljung_box_lags)
    assert whiteness.passed == all(q <= d.ljung_box_upper for q in d.ljung_box_statistic)
    assert whiteness.pvalue == pytest.approx(min(1.0, 2 * min(d.ljung_box_pvalue)))
    expected = {"white": (True, True), "too_large": (False, True), "too_small": (False, True), "correlated": (True, False)}
    assert (size.passed, whiteness.passed) == expected[case]
    direction = {"too_large": "overconfident", "too_small": "underconfident"}.get(case)
    assert d.cause.direction == direction and d.cause.explained_by is None
    assert d.verdict == (CONSISTENT if d.consistent else d.cause.reason)
    document = d.as_dict()
    assert [part["name"] for part in document["parts"]] == ["nis", "ljung_box"]
    assert set(document["cause"]) == {"explained_by", "direction", "reason"}


def test_bounds_are_the_split_quantiles():
    d = innovation_diagnostics(np.random.default_rng(1).standard_normal((300, 2)), confidence=0.99)
    assert d.nis_lower == pytest.approx(stats.chi2.ppf(0.0025, 600) / 300)
    assert d.nis_upper == pytest.approx(stats.chi2.isf(0.0025, 600) / 300)
    table = acorr_ljungbox(np.random.default_rng(1).standard_normal((300, 2))[:, 0], lags=[20])
    assert d.ljung_box_statistic[0] == pytest.approx(float(table["lb_stat"].iloc[0]))


def test_correlated_component_is_named():
    d = innovation_diagnostics(CASES["correlated"](np.random.default_rng(5)), confidence=0.99)
    assert "position innovations correlated in time" in d.verdict and "velocity innovations" not in d.verdict


def test_untestable_whiteness_is_not_a_pass():
    """A constant component has no Ljung-Box statistic (NaN): the whiteness part fails and says why."""
    innovations = np.random.default_rng(2).standard_normal((300, 2))
    innovations[:, 1] = 0.0
    d = innovation_diagnostics(innovations, confidence=0.99)
    assert not d.parts[1].passed and np.isnan(d.parts[1].pvalue) and not d.consistent
    assert "velocity innovations not testable for whiteness" in d.verdict and "position innovations" not in d.verdict


def test_confidence_outside_the_unit_interval_is_refused():
    with pytest.raises(ValueError, match="confidence"):
        innovation_diagnostics(np.zeros((10, 2)), confidence=1.0)


def test_the_whiteness_parts_statistic_does_not_depend_on_the_order_of_a_constant_component():
    """A constant component has no Ljung-Box statistic (NaN): the part's statistic is the other
    component's, whichever column comes first."""
    rng = np.random.default_rng(4)
    correlated = np.empty(300)
    correlated[0] = rng.standard_normal()
    for k in range(1, 300):
        correlated[k] = 0.6 * correlated[k - 1] + rng.standard_normal()
    constant = np.ones(300)
    first = innovation_diagnostics(np.column_stack([constant, correlated]), ("a", "b"), 0.99)
    second = innovation_diagnostics(np.column_stack([correlated, constant]), ("b", "a"), 0.99)
    (lb_first,) = [part for part in first.parts if part.name == "ljung_box"]
    (lb_second,) = [part for part in second.parts if part.name == "ljung_box"]
    assert np.isfinite(lb_first.statistic) and lb_first.statistic == lb_second.statistic
    assert "p = nan" not in first.verdict and "p = nan" not in second.verdict


def test_a_monte_carlo_pvalue_at_its_floor_prints_as_below_it():
    """No simulated white series reaches an AR(1) series' Ljung-Box statistic: its Monte Carlo p-value is the
    floor 1 / (1 + B) = 1 / 8,000, which bounds the tail probability from above, not equals it. It printed
    as 'p = 0.00013'."""
    from kalcal.calibration.diagnostics import monte_carlo_pvalue_text

    d = innovation_diagnostics(CASES["correlated"](np.random.default_rng(5)), confidence=0.99)
    assert min(d.ljung_box_pvalue) == pytest.approx(1 / 8000, rel=1e-12)  # B = 7,999 at the 0.25% tail
    assert "p < 0.00013 against" in d.verdict and "p = 0.00013" not in d.verdict
    assert monte_carlo_pvalue_text(1 / 8000, 7999) == "p < 0.00013"
    assert monte_carlo_pvalue_text(2 / 8000, 7999) == "p = 0.00025"  # above the floor: the value itself
    assert monte_carlo_pvalue_text(1 / 100, 99) == "p ≤ 0.01"  # a floor that two digits show exactly
    assert monte_carlo_pvalue_text(1 / 3, 2) == "p < 0.35"  # rounded up, never below the floor
