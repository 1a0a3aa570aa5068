"""The shape check: its grid statistic against the full Kolmogorov-Smirnov statistic, its false alarm under
the null (binomial bound over seeds), its power against Student-t noise, and the compiled histograms against
the numpy definition."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

from kalcal.montecarlo.accumulators import SHAPE_BINS, shape_grid, shape_histogram, shape_points
from kalcal.montecarlo.sum_kernels import add_shape
from kalcal.stats.distributions import binom_interval as clopper_pearson
from kalcal.stats.distributions import binom_isf
from kalcal.stats.shape import check_shape, grid_ks, grid_steps, ks_bound, ks_pvalue

INFO = SimpleNamespace(update_times=np.arange(1.0, 101.0))


def _statistics(nees: np.ndarray, nis: np.ndarray, d: int, p: int) -> SimpleNamespace:
    """What check_shape reads of an ensemble: N values (N, K) of each statistic."""
    n, k = nees.shape
    return SimpleNamespace(
        count=n,
        mean_error=np.zeros((k, d)),
        mean_residual=np.zeros((k, p)),
        nees_histogram=shape_histogram(nees, d),
        nis_histogram=shape_histogram(nis, p),
    )


@pytest.mark.parametrize("dof", [1, 2, 3, 7])
def test_grid_statistic_never_exceeds_the_full_one_and_misses_it_by_at_most_a_step(dof):
    rng = np.random.default_rng(dof)
    values = rng.chisquare(dof, size=(2000, 6))
    values[:, 3] *= 1.2  # an alternative too: the inequality holds for any sample
    grid, _ = grid_ks(shape_histogram(values, dof), dof)
    step = grid_steps(dof, SHAPE_BINS)
    assert step < 0.004
    for k in range(values.shape[1]):
        full = stats.kstest(values[:, k], stats.chi2(dof).cdf).statistic
        assert grid[k] <= full + 1e-12
        assert grid[k] >= full - step - 1e-12


def test_histogram_bins_are_equal_in_sqrt_x():
    rng = np.random.default_rng(5)
    values = rng.chisquare(3, size=(20000, 1))
    points = np.concatenate([[0.0], shape_points(3), [np.inf]])
    expected, _ = np.histogram(values[:, 0], bins=points)
    np.testing.assert_array_equal(shape_histogram(values, 3)[0], expected)


@pytest.mark.parametrize("dof", [1, 2, 4, 12])
def test_the_compiled_bins_are_numpys(dof):
    rng = np.random.default_rng(dof)
    points = shape_points(dof)
    values = np.concatenate([
        rng.chisquare(dof, 20000), points, np.nextafter(points, 0), np.nextafter(points, np.inf),
        [0.0, -1.0, 1e-300, 1e6, np.inf, np.nan],
    ])
    histogram = np.zeros((2, SHAPE_BINS), dtype=np.int64)
    add_shape(1, values, shape_grid(dof).scale, histogram)
    np.testing.assert_array_equal(histogram[1], shape_histogram(values[:, None], dof)[0])
    assert not histogram[0].any() and histogram[1].sum() == values.size


def test_pvalue_and_bound_agree():
    bound = ks_bound(0.01, 150, 10000)
    assert ks_pvalue(bound, 10000) * 150 == pytest.approx(0.01, rel=1e-6)
    # the union bound against the exact two-sided law: conservative, and close where it decides
    exact = stats.kstwo.sf(bound, 10000)
    assert exact <= ks_pvalue(bound, 10000) <= exact * (1 + 1e-3)


def _null_rejections(trials: int, n: int, k: int, confidence: float, seed: int) -> int:
    rng = np.random.default_rng(seed)
    failed = 0
    for _ in range(trials):
        s = _statistics(rng.chisquare(3, size=(n, k)), rng.chisquare(2, size=(n, k)), 3, 2)
        failed += not check_shape(s, INFO, confidence).passed
    return failed


def test_false_alarm_under_the_null_within_its_binomial_bound():
    """Conservative: at alpha = 0.05 the rejections of 300 null ensembles stay below Binomial(300, 0.05)'s
    upper 0.001 quantile."""
    trials, alpha = 300, 0.05
    failed = _null_rejections(trials, 400, 10, 1.0 - alpha, 11)
    assert failed <= binom_isf(0.001, trials, alpha)


@pytest.mark.slow
def test_false_alarm_under_the_null_within_its_binomial_bound_long():
    trials, alpha = 3000, 0.05
    failed = _null_rejections(trials, 1000, 20, 1.0 - alpha, 12)
    assert failed <= binom_isf(0.001, trials, alpha)


def test_heavy_tails_with_the_right_variance_fail():
    """Student t(5) components scaled to unit variance: NIS with mean p, not chi-square(p)."""
    rng = np.random.default_rng(3)
    n, k = 2000, 10
    t = rng.standard_t(5, size=(n, k, 2)) * np.sqrt(3 / 5)
    nis = (t**2).sum(axis=2)
    assert abs(nis.mean() - 2) < 5 * np.sqrt(16 / (n * k))  # second moment right (Var t^2 = 8 per component)
    s = _statistics(rng.chisquare(3, size=(n, k)), nis, 3, 2)
    result = check_shape(s, INFO, 0.99)
    assert not result.passed
    assert [part.passed for part in result.parts] == [True, False]
    assert "NIS is not chi-square(2)" in result.detail


def test_clopper_pearson():
    low, high = clopper_pearson(60, 60, 0.99)
    assert low == pytest.approx(0.005 ** (1 / 60)) and high == 1.0
    low, high = clopper_pearson(3, 100, 0.95)
    ref = stats.binomtest(3, 100).proportion_ci(0.95, method="exact")
    assert (low, high) == pytest.approx((ref.low, ref.high))


def test_histograms_that_miss_values_are_refused():
    """A block path that summed the moments without binning its values is a bug, never a pass or a fail."""
    rng = np.random.default_rng(1)
    s = _statistics(rng.chisquare(3, size=(100, 4)), rng.chisquare(2, size=(100, 4)), 3, 2)
    s.nis_histogram = s.nis_histogram * 0
    with pytest.raises(ValueError, match="nis_histogram"):
        check_shape(s, INFO, 0.99)


@pytest.mark.parametrize("count", [500, 20_000, 20_001, 300_000])
def test_the_bound_and_the_pvalue_are_one_law_on_both_sides_of_the_exact_count(count):
    """ks_bound inverts ks_pvalue whether the law is Smirnov's exact one or Massart's bound of it."""
    from kalcal.stats.shape import ks_bound, ks_pvalue

    bound = ks_bound(0.01, 150, count)
    np.testing.assert_allclose(ks_pvalue(bound, count), 0.01 / 150, rtol=1e-6)


@pytest.mark.parametrize("d", [0.004, 0.008, 0.012, 0.02])
def test_above_the_exact_count_the_pvalue_is_never_below_the_exact_one(d):
    """Massart's exp(-2 N d^2) bounds Smirnov's exact one-sided tail from above: the p-value used above
    EXACT_COUNT values is conservative (checked against the exact law just above the switch)."""
    from scipy import special

    from kalcal.stats.shape import EXACT_COUNT, ks_pvalue

    count = EXACT_COUNT + 1
    exact = min(1.0, 2.0 * float(special.smirnov(count, d)))
    assert float(ks_pvalue(d, count)) >= exact
