"""The residual whiteness check's two parts: the portmanteau's law under a correct filter, and which part finds what.

Ensembles of innovations are drawn here (a correct Kalman filter run in numpy, or Gaussian innovations
with a chosen correlation in time) and turned into the ensemble statistics the check reads; the
portmanteau is computed again from the realizations themselves, by orthonormal bases of each update's
span (Q = N sum_{j<k} ||Q_k^T Q_j||_F^2), as an oracle independent of the whitened moments.
"""

import numpy as np
import pytest
from scipy import stats

from kalcal.montecarlo.accumulators import EnsembleStatistics
from kalcal.montecarlo.problem import ProblemInfo
from kalcal.stats.bounds import normal_bound_at, portmanteau_bound, whiteness_pairs_bound
from kalcal.stats.text import check_bounds_text
from kalcal.stats.whiteness import check_residual_whiteness, portmanteau


def _info(n_updates, p):
    return ProblemInfo(
        "synthetic",
        np.arange(1, n_updates + 1, dtype=float),
        ("x",),
        ("m",),
        tuple(f"z{a}" for a in range(p)),
        ("m",) * p,
    )


def _statistics(r):
    """The ensemble statistics of innovations r (N, K, p) that the whiteness check reads (the rest placeholders)."""
    n, n_updates, p = r.shape
    stacked = r.reshape(n, n_updates * p)
    moment = (stacked.T @ stacked / n).reshape(n_updates, p, n_updates, p)
    one = np.ones((n_updates, 1, 1))
    return EnsembleStatistics(
        count=n,
        mean_error=np.zeros((n_updates, 1)),
        error_cov=one,
        error_second_moment=one,
        estimate_second_moment=one,
        error_estimate=np.zeros((n_updates, 1, 1)),
        mean_estimate=np.zeros((n_updates, 1)),
        filter_cov=one,
        mean_nees=np.ones(n_updates),
        mean_nis=np.full(n_updates, float(p)),
        mean_residual=r.mean(axis=0),
        residual_own_moment=np.einsum("nka,nkb->kab", r, r) / n,
        residual_second_moment=moment,
    )


def _oracle(r, centered=False):
    """N sum_{j<k} tr(P_k P_j), P_k the projection onto the span of update k's realizations (N - 1 if centered)."""
    n, n_updates, _ = r.shape
    if centered:
        r = r - r.mean(axis=0)
    bases = [np.linalg.qr(r[:, k, :])[0] for k in range(n_updates)]
    total = sum(np.sum((bases[k].T @ bases[j]) ** 2) for k in range(n_updates) for j in range(k))
    return (n - 1 if centered else n) * total


def _kalman_innovations(rng, n, n_updates):
    """Innovations of a correct filter: constant velocity (dt 0.5 s), position and velocity measured, (n, K, 2).

    Its S_k varies with k and correlates the two components, so the whitening has work to do."""
    dt = 0.5
    phi = np.array([[1.0, dt], [0.0, 1.0]])
    q = 0.3 * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    v = np.diag([0.5, 0.2])
    m0 = np.diag([4.0, 1.0])
    x = rng.multivariate_normal(np.zeros(2), m0, size=n)
    xhat, cov = np.zeros((n, 2)), m0
    r = np.empty((n, n_updates, 2))
    for k in range(n_updates):
        x = x @ phi.T + rng.multivariate_normal(np.zeros(2), q, size=n)
        z = x + rng.multivariate_normal(np.zeros(2), v, size=n)
        xbar, prior = xhat @ phi.T, phi @ cov @ phi.T + q
        s = prior + v
        gain = np.linalg.solve(s, prior).T
        r[:, k] = z - xbar
        xhat = xbar + r[:, k] @ gain.T
        cov = (np.eye(2) - gain) @ prior
    return r


def test_portmanteau_of_a_correct_filter_is_chi_square_on_its_degrees_of_freedom():
    """200 ensembles (N = 150, K = 8, p = 2: 112 degrees of freedom) of a correct filter's innovations.

    Its mean is the degrees of freedom exactly at every N (module docstring), so the mean of 200 lies within
    4 standard errors sqrt(2 dof / 200) (the chi-square's variance, above the exact one); the part fails at
    most at its alpha share (5% at 90% confidence): its rejections lie within Binomial(200, 0.05)'s 0.1% and
    99.9% quantiles; and a KS test against chi-square(112) does not reject at 0.1%. The centered statistic
    has the same law with N - 1, and the statistic equals the oracle from the realizations.
    """
    runs, n, n_updates, p, confidence = 200, 150, 8, 2, 0.90
    dof = p * p * n_updates * (n_updates - 1) // 2
    r_all = _kalman_innovations(np.random.default_rng(11), runs * n, n_updates).reshape(runs, n, n_updates, p)
    info = _info(n_updates, p)
    raw, centered, part_failures, check_failures = [], [], 0, 0
    for r in r_all:
        s = _statistics(r)
        check = check_residual_whiteness(s, info, confidence)
        pairs, port = check.parts
        assert port.statistic == pytest.approx(_oracle(r), rel=1e-9)
        q_c = portmanteau(s.residual_second_moment, s.mean_residual, n)
        assert q_c.statistic == pytest.approx(_oracle(r, centered=True), rel=1e-9)
        assert q_c.dof == dof
        raw.append(port.statistic)
        centered.append(q_c.statistic)
        part_failures += not port.passed
        check_failures += not check.passed
    assert port.upper == pytest.approx(stats.chi2.isf(0.05, dof)) and port.comparisons == 1
    se = np.sqrt(2 * dof / runs)
    assert abs(np.mean(raw) - dof) < 4 * se
    assert abs(np.mean(centered) - dof) < 4 * se
    assert stats.binom.ppf(0.001, runs, 0.05) <= part_failures <= stats.binom.ppf(0.999, runs, 0.05)
    assert check_failures <= stats.binom.ppf(0.999, runs, 1 - confidence)
    assert stats.kstest(raw, stats.chi2(dof).cdf).pvalue > 0.001


K, P, N = 40, 2, 400  # 3,120 comparisons (and degrees of freedom)
M = P * P * K * (K - 1) // 2
RUNS = 30


def _correlated_innovations(rng, correlation):
    """Gaussian innovations (N, K, P) of unit variance whose stacked correlation matrix is ``correlation``."""
    chol = np.linalg.cholesky(correlation)
    return (rng.standard_normal((N, K * P)) @ chol.T).reshape(N, K, P)


def _spread(delta, seed=5):
    """Every pair of components at different updates correlated by +-delta / sqrt(N) (seeded signs)."""
    signs = np.sign(np.random.default_rng(seed).standard_normal((K * P, K * P)))
    signs = np.triu(signs, 1) + np.triu(signs, 1).T
    same_update = np.kron(np.eye(K), np.ones((P, P))) > 0
    correlation = np.where(same_update, 0.0, signs * delta / np.sqrt(N)) + np.eye(K * P)
    assert np.linalg.eigvalsh(correlation).min() > 0.1
    return correlation


def _single(delta, k=30, j=12):
    """One element, z0 at update k with z1 at update j, correlated by delta / sqrt(N); the rest white."""
    correlation = np.eye(K * P)
    correlation[k * P, j * P + 1] = correlation[j * P + 1, k * P] = delta / np.sqrt(N)
    return correlation


def _power(delta_per_element, elements):
    """Powers (pairs, portmanteau) at 99% (alpha / 2 each) for ``elements`` elements of mean shift delta sigma.

    The pairs part: at most the union bound elements * P(|N(delta, 1)| > b) plus (M - elements) times the null
    rate per comparison, and at least P(|N(delta, 1)| > b) for one; the portmanteau: noncentral chi-square
    with lambda = elements * delta^2."""
    share = 0.005
    b = whiteness_pairs_bound(0.99, K, P)
    one = stats.norm.sf(b - delta_per_element) + stats.norm.sf(b + delta_per_element)
    pairs_upper = min(1.0, elements * one + (M - elements) * share / M)
    portmanteau_power = stats.ncx2.sf(portmanteau_bound(share, M), M, elements * delta_per_element**2)
    return one, pairs_upper, portmanteau_power


def _detections(correlation):
    pairs = portmanteau_ = 0
    info = _info(K, P)
    for seed in range(RUNS):
        check = check_residual_whiteness(_statistics(_correlated_innovations(np.random.default_rng(100 + seed), correlation)), info, 0.99)
        pairs += not check.parts[0].passed
        portmanteau_ += not check.parts[1].passed
    return pairs, portmanteau_


def test_a_thin_correlation_over_every_pair_is_found_by_the_portmanteau_not_by_the_largest_z():
    """Correlation +-0.025 (0.5 standard errors) on all 3,120 elements: the largest |z| stays below its bound of
    about 4.9 (power at most 3%), while the squares add up to a noncentrality of 780 (portmanteau power ~1)."""
    _, pairs_upper, port_power = _power(0.5, M)
    assert pairs_upper < 0.03 and port_power > 0.999
    pairs, port = _detections(_spread(0.5))
    assert port >= stats.binom.ppf(0.001, RUNS, 0.99)
    assert pairs <= stats.binom.ppf(0.999, RUNS, 0.03)


def test_a_single_strong_pair_is_found_by_the_largest_z_at_least_as_well():
    """One element at 0.35 (7 standard errors): the pairs part finds it (power > 0.98), the portmanteau, with a
    noncentrality of 49 among 3,120 degrees of freedom, mostly not (power about 0.03)."""
    pairs_lower, _, port_power = _power(7.0, 1)
    assert pairs_lower > 0.98 and port_power < 0.1
    pairs, port = _detections(_single(7.0))
    assert pairs >= stats.binom.ppf(0.001, RUNS, 0.98)
    assert port <= stats.binom.ppf(0.999, RUNS, port_power)  # the computed power, not a round ceiling
    assert pairs >= port


def test_nonzero_mean_residuals_fail_the_raw_check_and_the_centered_names_them():
    """White innovations with a mean of 0.115 sd at every update: E[r_k r_j] = 0.0132 on all 780 pairs, which the
    portmanteau (noncentrality ~ 780 x 2000 x 0.0131^2 = 270) finds and the pairs part (0.59 sd per pair
    against a bound of 4.5) does not; centered on the means both pass, and the cause says the mean residuals
    account for it."""
    n, n_updates = 2000, 40
    r = np.random.default_rng(3).standard_normal((n, n_updates, 1)) + 0.115
    check = check_residual_whiteness(_statistics(r), _info(n_updates, 1), 0.99)
    pairs, port = check.parts
    assert not check.passed and pairs.passed and not port.passed
    assert check.cause.explained_by == "mean_error"
    assert "nonzero mean residuals account for it" in check.detail and check.cause.reason in check.detail
    correlated = check_residual_whiteness(_statistics(_correlated_innovations(np.random.default_rng(4), _spread(0.5)) + 0.2), _info(K, P), 0.99)
    assert not correlated.passed and correlated.cause.explained_by is None
    assert "correlated in time" in correlated.cause.reason


def test_the_pvalue_is_the_parts_and_the_bounds_are_shown_for_both():
    r = _correlated_innovations(np.random.default_rng(6), _spread(0.5))
    check = check_residual_whiteness(_statistics(r), _info(K, P), 0.99)
    pairs, port = check.parts
    assert (pairs.name, port.name) == ("pairs", "portmanteau")
    assert pairs.alpha == port.alpha == pytest.approx(0.005)
    assert check.pvalue == pytest.approx(min(1.0, 2 * min(pairs.pvalue, port.pvalue)))
    assert check.passed == (pairs.passed and port.passed) == (check.pvalue >= 0.01)
    assert (check.statistic, check.upper) == (pairs.statistic, pairs.upper)
    assert pairs.upper == pytest.approx(normal_bound_at(0.005, M)) and port.upper == pytest.approx(stats.chi2.isf(0.005, M))
    assert port.pvalue == pytest.approx(stats.chi2.sf(port.statistic, M))
    assert check.comparisons == M + 1
    assert check_bounds_text(check.as_dict()) == f"pairs ≤ {pairs.upper:.4g}; portmanteau ≤ {port.upper:.4g}"


def test_an_update_without_power_leaves_its_degrees_of_freedom_out():
    """A component with zero variance at one update: its pairs have no whitened direction (rank 1 of 2)."""
    r = np.random.default_rng(8).standard_normal((500, 4, 2))
    r[:, 2, 1] = 0.0
    q = portmanteau(_statistics(r).residual_second_moment, None, 500)
    ranks = np.array([2, 2, 1, 2])
    assert q.dof == (ranks.sum() ** 2 - (ranks**2).sum()) // 2
    assert q.statistic == pytest.approx(_rank_oracle(r), rel=1e-9)


def _rank_oracle(r):
    n, n_updates, _ = r.shape
    bases = []
    for k in range(n_updates):
        u, sv, _ = np.linalg.svd(r[:, k, :], full_matrices=False)
        bases.append(u[:, sv > 1e-9 * sv.max()])
    return n * sum(np.sum((bases[k].T @ bases[j]) ** 2) for k in range(n_updates) for j in range(k))
