"""Each check and each part of a check fails a correct filter at most at its own share of alpha, at N = 100 and 400.

The ensembles are drawn from the exact laws of a correct filter's moments (``_null_ensembles``: Wishart
scatter, normal means, the innovations' own Gram matrix), so tens of thousands cost seconds. A check
or part held to a rate a fails a number of them that is stochastically below Binomial(M, a); each
assertion allows its 99.99% quantile (a correct implementation fails one of these assertions with
probability at most 1e-4 each).

The element-wise covariance test of the earlier code (version 2114039: a normal approximation to each
element, sd^2 = (P_il^2 + P_ii P_ll) / N), run on the slow test's own draws (its seeds, 20,000 ensembles;
2114039's ``kalcal.stats`` extracted with ``git archive`` and first on the path), failed 697
(3.49%) of them at N = 100 and 257 (1.29%) at N = 400 against its 0.5% share (the whole covariance
check 792 and 335, its mean_error 430 and 233); the slow test's bound at M = 20,000 is 0.70%. The
default-suite version (M = 2,000 at N = 100, seed 1, bound 24 failures) catches it too: the earlier
code failed 66 (3.30%) of its draws in ``elements``.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy import stats

from kalcal.stats.mean_error import check_mean_error
from kalcal.stats.nis import check_nis
from kalcal.stats.orthogonality import check_orthogonality
from kalcal.stats.covariance import check_covariance, correlation_z, t_equivalent_z, whitened_moments
from kalcal.stats.distributions import chi2_sf, normal_sf
from kalcal.stats.results import chi2_two_sided_pvalues
from kalcal.stats.whiteness import check_residual_whiteness

from . import _null_ensembles as null

CONFIDENCE = 0.99
ALPHA = 1.0 - CONFIDENCE
#: each part's share of its check's alpha
SHARES = {
    "mean_error": ALPHA,
    "covariance": ALPHA,
    "elements": ALPHA / 2,
    "centered_nees": ALPHA / 2,
    "orthogonality": ALPHA,
    "residual_whiteness": ALPHA,
    "pairs": ALPHA / 2,
    "portmanteau": ALPHA / 2,
    "nis": ALPHA,
}


def _limit(runs: int, rate: float) -> int:
    return int(stats.binom.ppf(1 - 1e-4, runs, rate))


def _state_failures(n: int, runs: int, n_updates: int = 150, d: int = 3, seed: int = 0) -> dict[str, int]:
    """Failures of mean_error, covariance (and its parts) and orthogonality over ``runs`` null ensembles."""
    rng = np.random.default_rng(seed)
    info = null.info(n_updates, d, 1)
    p_cov = null.filter_covariances(rng, n_updates, d)
    failures = dict.fromkeys(("mean_error", "covariance", "elements", "centered_nees", "orthogonality"), 0)
    done = 0
    while done < runs:
        size = min(500, runs - done)
        for s in null.state_statistics(rng, p_cov, n, size):
            cov = check_covariance(s, info, CONFIDENCE)
            failures["covariance"] += not cov.passed
            failures["elements"] += not cov.parts[0].passed
            failures["centered_nees"] += not cov.parts[1].passed
            failures["mean_error"] += not check_mean_error(s, info, CONFIDENCE).passed
            failures["orthogonality"] += not check_orthogonality(s, info, CONFIDENCE).passed
        done += size
    return failures


def _whiteness_failures(n: int, runs: int, n_updates: int = 100, seed: int = 0) -> dict[str, int]:
    """Failures of the whiteness parts (and the nis check) over ``runs`` null ensembles of scalar innovations.

    The parts' statistics and the nis check's p-value are formed for a batch of ensembles at once (the pairs' t-correlations and the
    portmanteau N sum_{j<k} r_kj^2 of the whitened moments, p = 1), as the check forms them one ensemble
    at a time; :func:`test_the_batched_whiteness_parts_are_the_checks` holds the two to each other.
    """
    rng = np.random.default_rng(seed)
    failures = dict.fromkeys(("residual_whiteness", "pairs", "portmanteau", "nis"), 0)
    m = n_updates * (n_updates - 1) // 2
    lower = np.tril(np.ones((n_updates, n_updates), dtype=bool), -1)
    done = 0
    while done < runs:
        size = min(500, runs - done)
        scale = np.exp(rng.uniform(-2, 2, n_updates))
        r = rng.standard_normal((size, n, n_updates)) * scale
        gram = np.swapaxes(r, 1, 2) @ r / n  # (size, K, K)
        p_pairs, p_port = _batched_parts(gram, n, lower, m)
        failures["pairs"] += int(np.count_nonzero(p_pairs < ALPHA / 2))
        failures["portmanteau"] += int(np.count_nonzero(p_port < ALPHA / 2))
        failures["residual_whiteness"] += int(np.count_nonzero(2 * np.minimum(p_pairs, p_port) < ALPHA))
        # N times a mean NIS of scalar innovations is chi-square(N), independent across updates
        p_nis = chi2_two_sided_pvalues(rng.chisquare(n, (size, n_updates)) / n, n, n)
        failures["nis"] += int(np.count_nonzero(np.minimum(1.0, n_updates * p_nis.min(axis=1)) < ALPHA))
        done += size
    return failures


def _batched_parts(gram: np.ndarray, n: int, lower: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
    """The pairs and portmanteau p-values of a batch of scalar-innovation second moments (size, K, K)."""
    power = np.diagonal(gram, axis1=1, axis2=2)
    z, _, _ = correlation_z(gram, power[:, :, None] * power[:, None, :], n - 1)
    worst = np.max(np.abs(np.where(lower, z, 0.0)), axis=(1, 2))
    p_pairs = np.minimum(1.0, m * 2.0 * normal_sf(worst))
    r = gram / np.sqrt(power[:, :, None] * power[:, None, :])
    q = n * np.sum(np.where(lower, r, 0.0) ** 2, axis=(1, 2))
    return p_pairs, chi2_sf(q, m)


def _assert_rates(failures: dict[str, int], runs: int, n: int) -> None:
    rates = {name: f"{count} ({100 * count / runs:.3f}%)" for name, count in failures.items()}
    print(f"N = {n}, {runs} ensembles: failures {rates}")
    over = {
        name: (count, _limit(runs, SHARES[name]))
        for name, count in failures.items()
        if count > _limit(runs, SHARES[name])
    }
    assert not over, (n, over)


@pytest.mark.slow
@pytest.mark.parametrize("n", [100, 400])
def test_state_checks_and_parts_at_their_rates(n):
    """20,000 ensembles, K = 150, d = 3 (the discrete-truth default's 900 element comparisons)."""
    runs = 20000
    _assert_rates(_state_failures(n, runs, seed=n), runs, n)


@pytest.mark.slow
@pytest.mark.parametrize("n", [100, 400])
def test_whiteness_parts_and_nis_at_their_rates(n):
    """20,000 ensembles, K = 100 updates of a scalar innovation (4,950 pairs)."""
    runs = 20000
    _assert_rates(_whiteness_failures(n, runs, seed=n), runs, n)


def test_state_checks_and_parts_at_their_rates_fast():
    """The default suite's version: 2,000 ensembles at N = 100 (the elements part's bound is 1.2%: it
    catches the earlier code's 3.49%, not a rate just above the share; the slow test decides those)."""
    runs = 2000
    _assert_rates(_state_failures(100, runs, seed=1), runs, 100)


def test_whiteness_parts_at_their_rates_fast():
    runs = 2000
    _assert_rates(_whiteness_failures(100, runs, seed=1), runs, 100)


@pytest.mark.parametrize("p", [1, 2])
def test_the_batched_whiteness_parts_are_the_checks(p):
    """The batch above forms the parts' p-values as the check does: equal to rounding on a few ensembles
    (p = 1; the nis p-value at p = 1 and 2). The batch is of scalar innovations only: the check itself
    at p = 2 is held to its rates by :func:`test_whiteness_and_nis_checks_at_their_rates_with_two_measurements`."""
    rng = np.random.default_rng(3)
    n_updates, n = 30, 100
    lower = np.tril(np.ones((n_updates, n_updates), dtype=bool), -1)
    for _ in range(5):
        s = null.innovation_statistics(rng, n_updates, p, n)
        check = check_residual_whiteness(s, null.info(n_updates, 1, p), CONFIDENCE)
        nis = check_nis(s, null.info(n_updates, 1, p), CONFIDENCE)
        expected = min(1.0, n_updates * chi2_two_sided_pvalues(s.mean_nis, n * p, n).min())
        assert nis.pvalue == pytest.approx(expected, rel=1e-12)
        if p == 1:
            p_pairs, p_port = _batched_parts(s.residual_second_moment[None, :, 0, :, 0], n, lower, n_updates * (n_updates - 1) // 2)
            assert check.parts[0].pvalue == pytest.approx(float(p_pairs[0]), rel=1e-9)
            assert check.parts[1].pvalue == pytest.approx(float(p_port[0]), rel=1e-9)
        else:
            assert check.parts[0].comparisons == p * p * n_updates * (n_updates - 1) // 2


def _own_cov_failures(n: int, runs: int, n_updates: int = 150, d: int = 3, seed: int = 0) -> tuple[dict, dict]:
    """Failures of the state checks over ``runs`` null ensembles whose P_k differs between realizations
    (``_null_ensembles.own_cov_statistics``): each realization whitened by its own P_k, and the same
    ensembles whitened by the mean P (the per-realization sums dropped)."""
    rng = np.random.default_rng(seed)
    info = null.info(n_updates, d, 1)
    p_cov = null.filter_covariances(rng, n_updates, d)
    names = ("mean_error", "covariance", "elements", "centered_nees", "orthogonality")
    own, mean_p = dict.fromkeys(names, 0), dict.fromkeys(names, 0)
    for _ in range(runs):
        s = null.own_cov_statistics(rng, p_cov, n)
        for failures, stats_ in ((own, s), (mean_p, null.without_own_whitening(s))):
            cov = check_covariance(stats_, info, CONFIDENCE)
            failures["covariance"] += not cov.passed
            failures["elements"] += not cov.parts[0].passed
            failures["centered_nees"] += not cov.parts[1].passed
            failures["orthogonality"] += not check_orthogonality(stats_, info, CONFIDENCE).passed
            failures["mean_error"] += not check_mean_error(stats_, info, CONFIDENCE).passed
    return own, mean_p


def _assert_own_whitening_matters(n: int, runs: int, seed: int, exact_lower: bool = False) -> None:
    """Whitened realization by realization, each check and part inside its rate; whitened by the mean
    P, the covariance check fails far above it (more than half of the ensembles: the errors' scale
    mixture has variances far wider than chi-square's).

    ``exact_lower``: mean_error's K d whitened comparisons are independent t(N - 1) (the components of
    eps are iid N(0, 1) and independent across updates in these draws), so its Bonferroni family fails
    at exactly 1 - (1 - alpha / m)^m; its count must also stay above that rate's 0.01% binomial quantile
    (the raw mean over a standard error of errors of different variances, a scale mixture, fell below it)."""
    own, mean_p = _own_cov_failures(n, runs, seed=seed)
    print(f"whitened by the mean P: {mean_p}")
    _assert_rates(own, runs, n)
    assert mean_p["covariance"] > runs / 2, mean_p
    if exact_lower:
        m = 150 * 3
        exact = 1.0 - (1.0 - ALPHA / m) ** m
        assert own["mean_error"] >= stats.binom.ppf(1e-4, runs, exact), (own["mean_error"], exact)


def test_per_realization_whitening_holds_the_rates_where_p_varies_fast():
    """400 ensembles at N = 100 whose P_k differs between realizations."""
    _assert_own_whitening_matters(100, 400, seed=2)


@pytest.mark.slow
@pytest.mark.parametrize(("n", "runs"), [(100, 10000), (400, 3000)])
def test_per_realization_whitening_holds_the_rates_where_p_varies(n, runs):
    """10,000 ensembles at N = 100 and 3,000 at N = 400 (each drawn realization by realization)."""
    _assert_own_whitening_matters(n, runs, seed=n + 1, exact_lower=True)


def test_mean_error_tests_the_whitened_error_where_p_varies():
    """Where the whitened sums are kept, mean_error is the t(N - 1) of each whitened component's mean
    over its own standard error: a mean in the whitened errors alone fails it, and its statistic is
    that t's normal equivalent (the raw errors, of different variances, have no exact law)."""
    rng = np.random.default_rng(4)
    n_updates, d, n = 20, 3, 100
    info = null.info(n_updates, d, 1)
    s = null.own_cov_statistics(rng, null.filter_covariances(rng, n_updates, d), n)
    white = whitened_moments(s)
    t = white.mean / np.sqrt(np.diagonal(white.cov, axis1=1, axis2=2) / n)
    expected = float(np.max(np.abs(t_equivalent_z(t, n - 1))))
    assert check_mean_error(s, info, CONFIDENCE).statistic == pytest.approx(expected, rel=1e-12)
    # half a standard deviation in the whitened errors' mean, the raw sums untouched: t about 5 at N = 100
    shifted = dataclasses.replace(s, mean_whitened_error=s.mean_whitened_error + 0.5)
    result = check_mean_error(shifted, info, CONFIDENCE)
    assert not result.passed and "mean whitened error" in result.detail
    assert check_mean_error(null.without_own_whitening(shifted), info, CONFIDENCE).passed


def _check_failures_p2(n: int, runs: int, n_updates: int = 30, seed: int = 0) -> dict[str, int]:
    """Failures of the whiteness check itself (and its parts) and of nis over ``runs`` null ensembles of
    K updates of p = 2 correlated innovations (``_null_ensembles.innovation_statistics``), one at a time."""
    rng = np.random.default_rng(seed)
    info = null.info(n_updates, 1, 2)
    failures = dict.fromkeys(("residual_whiteness", "pairs", "portmanteau", "nis"), 0)
    for _ in range(runs):
        s = null.innovation_statistics(rng, n_updates, 2, n)
        check = check_residual_whiteness(s, info, CONFIDENCE)
        failures["residual_whiteness"] += not check.passed
        failures["pairs"] += not check.parts[0].passed
        failures["portmanteau"] += not check.parts[1].passed
        failures["nis"] += not check_nis(s, info, CONFIDENCE).passed
    return failures


def test_whiteness_and_nis_checks_at_their_rates_with_two_measurements():
    """The checks themselves (not the batch) at p = 2, K = 30, N = 100: 2,000 ensembles, each count
    within its share's 99.99% binomial quantile (4,000 ms-scale checks: about 8 s)."""
    runs = 2000
    _assert_rates(_check_failures_p2(100, runs, seed=5), runs, 100)


@pytest.mark.slow
@pytest.mark.parametrize("n", [100, 400])
def test_whiteness_and_nis_checks_at_their_rates_with_two_measurements_slow(n):
    """20,000 ensembles of the checks themselves at p = 2, K = 30."""
    runs = 20000
    _assert_rates(_check_failures_p2(n, runs, seed=n + 2), runs, n)
