"""Check results as data: p-values, causes, parts, zero standard errors, and the covariance check's rate.

These build ensemble statistics directly (no Monte Carlo), so each case is exact and fast.
"""

import json
from dataclasses import replace

import numpy as np
import pytest
from scipy import stats

from kalcal.io.results import to_jsonable
from kalcal.montecarlo.accumulators import EnsembleStatistics
from kalcal.stats.bounds import verdict_false_alarm_bound
from kalcal.stats.covariance import check_covariance
from kalcal.stats.mean_error import check_mean_error
from kalcal.stats.orthogonality import check_orthogonality
from kalcal.stats.results import Cause, CheckPart, CheckResult
from kalcal.stats.whiteness import check_residual_whiteness
from kalcal.stats.results import family_pvalue, normal_family_pvalue

from . import _null_ensembles as null


def _info(n_updates, d, p=1):
    return null.info(n_updates, d, p)


def _stats(n, error_cov, filter_cov, mean_error=None, **extra):
    """EnsembleStatistics of K updates and d states with the given moments; the rest consistent or zero."""
    n_updates, d, _ = error_cov.shape
    mean_error = np.zeros((n_updates, d)) if mean_error is None else mean_error
    second = error_cov * (n - 1) / n + mean_error[:, :, None] * mean_error[:, None, :]
    fields = dict(
        count=n,
        mean_error=mean_error,
        error_cov=error_cov,
        error_second_moment=second,
        estimate_second_moment=np.broadcast_to(np.eye(d), (n_updates, d, d)).copy(),
        error_estimate=np.zeros((n_updates, d, d)),
        mean_estimate=np.zeros((n_updates, d)),
        filter_cov=np.broadcast_to(filter_cov, (n_updates, d, d)).copy(),
        mean_nees=np.full(n_updates, float(d)),
        mean_nis=np.ones(n_updates),
        mean_residual=np.zeros((n_updates, 1)),
        residual_own_moment=np.ones((n_updates, 1, 1)),
        residual_second_moment=None,
    )
    fields.update(extra)
    return EnsembleStatistics(**fields)


def test_covariance_check_false_alarm_rate_is_at_most_one_minus_confidence():
    """Exact Wishart draws of a correct filter's ensemble covariance: the check fails at most alpha of them.

    The old check (element-wise family OR centered NEES, each at the full alpha) failed about 2 alpha of
    these (175 of 2000 at 95%). With alpha = 0.05 the failures of a check at rate <= alpha are
    stochastically below Binomial(2000, 0.05), whose 99.9% quantile is 131.
    """
    runs, n, d, confidence = 2000, 20000, 3, 0.95
    rng = np.random.default_rng(7)
    a = rng.standard_normal((d, d))
    p = a @ a.T + d * np.eye(d)
    draws = stats.wishart.rvs(df=n - 1, scale=p, size=runs, random_state=rng) / (n - 1)
    info = _info(1, d)
    failures = sum(not check_covariance(_stats(n, w[None], p), info, confidence).passed for w in draws)
    limit = stats.binom.ppf(0.999, runs, 1 - confidence)
    assert limit == 131
    assert failures <= limit


def test_zero_standard_error_with_a_nonzero_mean_fails_mean_error():
    """A state with no spread over the ensemble and a mean error of 0.5 is not a pass (z is infinite)."""
    d, n_updates = 2, 3
    error_cov = np.zeros((n_updates, d, d))
    error_cov[:, 0, 0] = 1.0
    mean = np.zeros((n_updates, d))
    mean[:, 1] = 0.5
    check = check_mean_error(_stats(1000, error_cov, np.eye(d), mean), _info(n_updates, d), 0.99)
    assert not check.passed and check.pvalue == 0.0 and np.isinf(check.statistic)
    assert "x1 at t = 1 s: mean error 0.5 with zero standard error" in check.detail
    assert "3 comparison(s) with zero standard error and a nonzero mean error, counted as failed" in check.detail
    assert check.cause.explained_by is None and check.cause.reason in check.detail
    # the predicted model error accounts for it exactly: explained, but still a failure
    explained = check_mean_error(_stats(1000, error_cov, np.eye(d), mean), _info(n_updates, d), 0.99, mean, "x")
    assert not explained.passed and explained.cause.explained_by == "model_error"
    assert json.loads(json.dumps(to_jsonable(check.as_dict())))["statistic"] is None  # JSON has no inf


def test_zero_standard_error_with_a_zero_mean_passes_and_is_counted():
    d, n_updates = 2, 3
    error_cov = np.zeros((n_updates, d, d))
    error_cov[:, 0, 0] = 1.0
    check = check_mean_error(_stats(1000, error_cov, np.eye(d)), _info(n_updates, d), 0.99)
    assert check.passed and check.statistic == 0.0 and check.pvalue == 1.0
    assert "3 comparison(s) with zero standard error and an exactly zero mean error, counted as passed" in check.detail


def test_zero_standard_error_in_orthogonality():
    """E[e xhat^T] with E[xhat^2] = 0 for a state: a nonzero moment fails, a zero one passes and is counted."""
    d, n_updates, n = 2, 2, 1000
    base = _stats(n, np.broadcast_to(np.eye(d), (n_updates, d, d)).copy(), np.eye(d))
    estimate = np.zeros((n_updates, d, d))
    estimate[:, 0, 0] = 1.0  # the estimate of x1 never moves
    info = _info(n_updates, d)
    zero = check_orthogonality(replace(base, estimate_second_moment=estimate), info, 0.99)
    assert zero.passed and "4 comparison(s) with zero standard error and an exactly zero moment" in zero.detail
    moment = np.zeros((n_updates, d, d))
    moment[1, 0, 1] = 1e-3
    bad = check_orthogonality(replace(base, estimate_second_moment=estimate, error_estimate=moment), info, 0.99)
    assert not bad.passed and bad.pvalue == 0.0 and np.isinf(bad.statistic)
    assert "1 comparison(s) with zero standard error and a nonzero moment, counted as failed" in bad.detail


def test_zero_standard_error_in_residual_whiteness():
    """An innovation with no power (E[r_k^2] = 0) at one update: its pairs pass only if exactly zero."""
    n_updates, n = 3, 1000
    power = np.array([1.0, 0.0, 1.0])
    moment = np.zeros((n_updates, 1, n_updates, 1))
    for k in range(n_updates):
        moment[k, 0, k, 0] = power[k]
    base = _stats(n, np.broadcast_to(np.eye(1), (n_updates, 1, 1)).copy(), np.eye(1))
    info = _info(n_updates, 1)
    quiet = check_residual_whiteness(replace(base, residual_second_moment=moment), info, 0.99)
    # pairs (1, 0) and (2, 1) involve the update without power; (2, 0) does not
    assert quiet.passed and "2 comparison(s) with zero standard error and an exactly zero moment" in quiet.detail
    moment = moment.copy()
    moment[2, 0, 1, 0] = moment[1, 0, 2, 0] = 1e-9
    loud = check_residual_whiteness(replace(base, residual_second_moment=moment), info, 0.99)
    assert not loud.passed and np.isinf(loud.statistic)
    assert "1 comparison(s) with zero standard error and a nonzero moment, counted as failed" in loud.detail


def test_results_refuse_a_pvalue_that_disagrees_with_passed():
    with pytest.raises(ValueError, match="disagrees"):
        CheckResult("x", 5.0, 0.001, None, 4.0, 0.99, 10, True, "d")
    with pytest.raises(ValueError, match="disagrees"):
        CheckPart("x", 1.0, 0.5, None, 4.0, 0.995, 0.005, 10, False)
    with pytest.raises(ValueError, match="explained_by"):
        Cause(explained_by="luck")
    with pytest.raises(ValueError, match="direction"):
        Cause(direction="sideways")


def test_as_dict_holds_pvalue_cause_and_parts():
    p = np.eye(2)
    check = check_covariance(_stats(1000, np.broadcast_to(4 * p, (2, 2, 2)).copy(), p), _info(2, 2), 0.99)
    document = json.loads(json.dumps(to_jsonable(check.as_dict())))
    assert set(document) == {
        "name", "statistic", "pvalue", "lower", "upper", "confidence", "comparisons", "passed", "detail", "cause",
        "parts", "measured", "effect_sizes", "within_tolerance", "tolerance_outcome",
    }
    assert document["detail"] == f"{document['measured']}. {document['cause']['reason']}"
    assert document["cause"]["reason"] not in document["measured"]
    assert document["cause"] == {
        "explained_by": None,
        "direction": "overconfident",
        "reason": "The filter is overconfident: its P is smaller than the actual spread (noise settings too small)",
    }
    assert [part["name"] for part in document["parts"]] == ["elements", "centered_nees"]
    for part in document["parts"]:
        assert set(part) == {"name", "statistic", "pvalue", "lower", "upper", "confidence", "alpha", "comparisons", "passed"}
        assert part["alpha"] == pytest.approx(0.005) and not part["passed"]


def test_pvalue_formulas():
    assert normal_family_pvalue(stats.norm.isf(0.0005), 10) == pytest.approx(0.01)
    assert normal_family_pvalue(0.0, 10) == 1.0
    assert normal_family_pvalue(np.inf, 10) == 0.0
    assert np.isnan(normal_family_pvalue(np.nan, 10))
    assert family_pvalue([0.2, 0.001, 0.5]) == pytest.approx(0.003)
    assert family_pvalue([0.6, 0.5]) == 1.0


def test_verdict_false_alarm_bound():
    assert verdict_false_alarm_bound(0.99, 5) == pytest.approx(0.05)
    assert verdict_false_alarm_bound(0.5, 5) == 1.0


@pytest.mark.parametrize("eps", [0.0, 0.001, -0.001])
def test_covariance_failing_off_the_diagonal_alone_states_no_direction(eps):
    """P = I2, C = [[1 + eps, 0.1], [0.1, 1]], N = 20000: (x0, x1) is 14.1 sd off, every variance agrees.

    The statistic is the |z| of the correlation's exact t(N - 2) p-value.

    The old rule took the sign of the largest diagonal z, which here is noise: ``underconfident`` for
    eps = 0 (argmax of zeros) and flipping with the sign of eps."""
    n = 20000
    c = np.array([[[1.0 + eps, 0.1], [0.1, 1.0]]])
    check = check_covariance(_stats(n, c, np.eye(2)), _info(1, 2), 0.99)
    elements, nees = check.parts
    assert not check.passed and not elements.passed and nees.passed
    r = 0.1 / np.sqrt(1.0 + eps)
    p = 2 * stats.t.sf(r * np.sqrt(n - 2) / np.sqrt(1 - r * r), n - 2)
    assert elements.statistic == pytest.approx(stats.norm.isf(p / 2), rel=1e-9)
    assert elements.statistic == pytest.approx(0.1 / np.sqrt(1 / n), rel=0.01)  # about 14.1 sd in (x0, x1)
    assert check.cause.direction is None and check.cause.explained_by is None
    assert check.cause.reason.startswith("The correlation of x0 and x1 differs from P's (the variances agree")
    assert check.detail.endswith(check.cause.reason)


@pytest.mark.parametrize("scale, direction", [(1.025, "overconfident"), (0.975, "underconfident")])
def test_covariance_failing_by_the_centered_nees_alone_takes_its_side(scale, direction):
    """C = scale I3 against P = I3, N = 20000: each variance is 2.5 sd off (inside the element-wise bound
    3.34 for 6 comparisons at alpha / 2), the centered NEES sqrt(3) times that (beyond its 2.81)."""
    n = 20000
    check = check_covariance(_stats(n, scale * np.eye(3)[None], np.eye(3)), _info(1, 3), 0.99)
    elements, nees = check.parts
    assert elements.passed and not nees.passed and not check.passed
    p = 2 * min(stats.chi2.sf((n - 1) * scale, n - 1), stats.chi2.cdf((n - 1) * scale, n - 1))
    assert elements.statistic == pytest.approx(stats.norm.isf(p / 2), rel=1e-9)
    assert elements.statistic == pytest.approx(0.025 / np.sqrt(2 / n), rel=0.02) and elements.statistic < elements.upper
    assert (nees.statistic > nees.upper) == (direction == "overconfident")
    assert (nees.statistic < nees.lower) == (direction == "underconfident")
    assert check.cause.direction == direction


def test_covariance_variances_failing_both_ways_state_no_direction():
    n = 20000
    c = np.diag([1.1, 0.9])[None]
    check = check_covariance(_stats(n, c, np.eye(2)), _info(1, 2), 0.99)
    assert not check.passed and check.cause.direction is None
    assert "whitened ensemble variance of x0 exceeds 1 and that of x1 falls short" in check.cause.reason


def test_covariance_variance_outside_the_bound_gives_the_direction_by_its_sign():
    """A failing diagonal decides, even where a larger off-diagonal deviation is what the headline shows."""
    n = 20000
    c = np.array([[[0.95, 0.3], [0.3, 1.0]]])
    check = check_covariance(_stats(n, c, np.eye(2)), _info(1, 2), 0.99)
    assert check.cause.direction == "underconfident"


def test_a_result_keeps_its_measured_text_apart_from_the_reason():
    cause = Cause(direction="overconfident", reason="Too small.")
    good = CheckResult("x", 5.0, 0.001, None, 4.0, 0.99, 10, False, "5 sd. Too small.", cause, measured="5 sd")
    assert good.as_dict()["measured"] == "5 sd"
    assert CheckResult("x", 1.0, 0.5, None, 4.0, 0.99, 10, True, "1 sd").measured == "1 sd"
    with pytest.raises(ValueError, match="measured text apart"):
        CheckResult("x", 5.0, 0.001, None, 4.0, 0.99, 10, False, "5 sd. Too small.", cause)
    with pytest.raises(ValueError, match="is not the measured text"):
        CheckResult("x", 5.0, 0.001, None, 4.0, 0.99, 10, False, "6 sd. Too small.", cause, measured="5 sd")


def test_far_off_statistics_are_finite_sd_continuous_with_the_exact_tail():
    """Beyond the smallest double the t and chi-square tails underflow; the sd-equivalent then comes from
    Wallace's transform (t) and the root of the deviance (chi-square, either side of the mean): finite,
    increasing away from the centre, and within 0.5% across the switch, measured on the function itself
    (the default run's mean error reaches t = 1092 at N = 300,000: 694 sd)."""
    from kalcal.stats.covariance import chi2_equivalent_z, t_equivalent_z
    from kalcal.stats.distributions import chi2_cdf, chi2_sf, t_sf

    tiny = np.finfo(float).tiny

    def switch(inside, lo, hi):
        """The last point (by bisection) where ``inside`` holds, between lo (inside) and hi (outside)."""
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if inside(mid) else (lo, mid)
        return lo, hi

    checked = []
    for dof in (98.0, 399.0, 299999.0):
        t = np.geomspace(1.0, 1e6, 4001)
        z = t_equivalent_z(t, dof)
        # increasing, but for the step at the switch (within 0.5%)
        assert np.all(np.isfinite(z)) and np.all(np.diff(z) > -5e-3 * z[1:]), dof
        a, b = switch(lambda x: t_sf(x, dof) >= tiny, 1.0, 1e6)
        near = t_equivalent_z(np.array([a, b]), dof)
        assert t_sf(b, dof) < tiny and abs(near[1] / near[0] - 1) < 5e-3, (dof, near)
        sd = np.sqrt(2 * dof)
        for lo, hi in ((dof + 3 * sd, 1e3 * dof), (dof - 3 * sd, 1e-6 * dof)):  # 3 sd above the mean, then below
            x = np.geomspace(lo, hi, 4001)
            zc = chi2_equivalent_z(x, dof)
            assert np.all(np.isfinite(zc)) and np.all(np.diff(zc) > -5e-3 * zc[1:]), (dof, lo, hi)
            inside = lambda v: min(chi2_cdf(v, dof), chi2_sf(v, dof)) >= tiny  # noqa: E731
            if inside(hi):
                continue  # no switch in this range (98 dof below the mean: the tail stays above 1e-274)
            a, b = switch(inside, lo, hi)
            near = chi2_equivalent_z(np.array([a, b]), dof)
            assert abs(near[1] / near[0] - 1) < 5e-3, (dof, lo, hi, near)
            checked.append((dof, lo < hi))
    # the switch was crossed above the mean at every dof, and below it at least once
    assert [c for c in checked if c[1]] == [(98.0, True), (399.0, True), (299999.0, True)]
    assert any(not above for _, above in checked)
    assert t_equivalent_z(np.array([np.inf, -np.inf]), 99.0).tolist() == [np.inf, -np.inf]
