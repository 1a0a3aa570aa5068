"""The Ljung-Box whiteness part of ``calibrate``'s diagnostics: a simulated null, so its size holds at every K.

Bounds are binomial quantiles from theory: under white N(0, I) innovations the NIS part fails with
probability alpha / 2 (exact) and the whiteness part with at most alpha / 2, so over n independent logs
the counts of failures are at most Binomial(n, alpha / 2) and Binomial(n, alpha) in distribution.
"""

import numpy as np
import pytest
from scipy import stats
from statsmodels.stats.diagnostic import acorr_ljungbox

from kalcal.calibration import ljung_box as lb
from kalcal.calibration.diagnostics import innovation_diagnostics


def _failures(rng, runs, fixes, confidence):
    """(# logs called inconsistent, # logs failing the whiteness part) over ``runs`` white logs (K, 2)."""
    whole = white = 0
    for _ in range(runs):
        d = innovation_diagnostics(rng.standard_normal((fixes, 2)), confidence=confidence)
        whole += not d.consistent
        white += not d.parts[1].passed
    return whole, white


def _ar1(rng, n, phi, columns):
    e = rng.standard_normal((n, columns))
    x = np.empty((n, columns))
    x[0] = e[0]
    for k in range(1, n):
        x[k] = phi * x[k - 1] + np.sqrt(1 - phi**2) * e[k]
    return x


@pytest.mark.parametrize(("fixes", "runs"), [(200, 2500), (2000, 1000)])
def test_white_logs_are_called_inconsistent_at_most_at_the_stated_rate(fixes, runs):
    """At 99%, short (K = 200) and 2000-fix logs: false alarms within Binomial(runs, 1%) and 0.5%.

    With the asymptotic chi-square reference, the whiteness part alone failed 2.8 times its 0.25% per
    component at K = 200 (about 1.4% of logs, some 35 of 2,500, against a bound of 25 here); K = 2000 logs
    take the null of 500 fixes, whose heavier tail makes the part conservative.
    """
    confidence = 0.99
    whole, white = _failures(np.random.default_rng(fixes), runs, fixes, confidence)
    alpha = 1 - confidence
    assert whole <= stats.binom.ppf(0.999, runs, alpha)
    assert white <= stats.binom.ppf(0.999, runs, alpha / 2)


def test_correlated_innovations_are_detected_at_200_fixes():
    """AR(1) innovations, phi = 0.3, in both components of K = 200 fixes, at 90%.

    The noncentral chi-square(20, lambda = K sum_h phi^(2h)) approximation of Q at the simulated bound
    gives a power of 0.59 per component, 0.83 for either; held here to at least 0.75 (the 0.1% binomial
    quantile), against at most 5% for white logs.
    """
    rng = np.random.default_rng(30)
    runs, detected = 300, 0
    for _ in range(runs):
        detected += not innovation_diagnostics(_ar1(rng, 200, 0.3, 2), confidence=0.9).parts[1].passed
    assert detected >= stats.binom.ppf(0.001, runs, 0.75)


def test_statistic_is_statsmodels_ljung_box():
    x = np.random.default_rng(4).standard_normal((3, 300))
    expected = [float(acorr_ljungbox(row, lags=[20])["lb_stat"].iloc[0]) for row in x]
    assert lb.ljung_box_statistics(x, 20) == pytest.approx(expected, rel=1e-10)
    assert np.isnan(lb.ljung_box_statistics(np.ones((1, 30)), 5)[0])
    with pytest.raises(ValueError, match="lags"):
        lb.ljung_box_statistics(x, 300)


def test_draws_resolve_the_smallest_tail():
    """(B + 1) tail = 20 draws: at 99%, per component 0.25%, B = 7999, and a statistic above every
    simulated one has p = 1 / 8000, well below the tail, so the part can reject."""
    assert lb.draws_for(0.005 / 2) == 7999 and lb.draws_for(0.05 / 2) == 799
    null = lb.simulated_null(200, 20, 7999)
    assert null.size == 7999 and np.all(np.diff(null) >= 0)
    assert lb.monte_carlo_pvalues(null, np.array([np.inf]))[0] == 1 / 8000
    # the bound at the family-wise share 0.5% (as 1 - 0.99 rounds, a hair above): a statistic fails exactly
    # when at most 19 simulated ones reach it, 20 of the 8,000 equally likely ranks under the null, 0.25%
    upper = lb.largest_passing(null, 2, (1 - 0.99) / 2)
    assert null[-20] < upper < null[-19]


def test_monte_carlo_pvalue_counts_ties_and_nan():
    null = np.array([1.0, 2.0, 3.0])
    p = lb.monte_carlo_pvalues(null, np.array([0.5, 2.0, 3.5, np.nan]))
    assert p[:3] == pytest.approx([1.0, 0.75, 0.25]) and np.isnan(p[3])


def test_two_fix_logs_never_fail_whiteness():
    """With K = 2 fixes Q is the same for every series (rho_1 = -1/2): the part has nothing to test and
    must pass, not fail on rounding."""
    rng = np.random.default_rng(6)
    assert all(innovation_diagnostics(rng.standard_normal((2, 2))).parts[1].passed for _ in range(50))


def test_long_logs_take_the_reference_length_null():
    """The simulation's cost is bounded: an 18,000-fix log (an hour of fixes at 5 Hz) uses the 500-fix null."""
    assert lb.simulated_null(18_000, 20, 7999) is lb.simulated_null(lb.REFERENCE_FIXES, 20, 7999)
    assert lb.simulated_null(300, 20, 7999)[0] != lb.simulated_null(200, 20, 7999)[0]


@pytest.mark.slow
@pytest.mark.parametrize("fixes", [1000, 5000])
def test_reference_null_is_conservative_for_longer_logs(fixes):
    """The 500-fix null's 0.25% bound against 20,000 independent white series of K fixes: they exceed it at
    most at 0.25% (Binomial 0.1% quantile); measured with 10^5 series, 0.85 and 0.62 times the rate."""
    null = lb.simulated_null(fixes, 20, 7999)
    upper = lb.largest_passing(null, 1, 0.0025)
    rng = np.random.default_rng([99, fixes])
    q = np.concatenate([lb.ljung_box_statistics(rng.standard_normal((1000, fixes)), 20) for _ in range(20)])
    assert np.sum(q > upper) <= stats.binom.ppf(0.999, q.size, 0.0025)
