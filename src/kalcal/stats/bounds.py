"""The bounds of the checks' families and of the verdict: normal and chi-square quantiles under Bonferroni.

A family of m comparisons held to a family-wise alpha tests each at alpha / m (two-sided: alpha / (2 m)
in each tail). The covariance check splits its alpha equally among its ``COVARIANCE_PARTS``, the
whiteness check among its ``WHITENESS_PARTS``.
"""

from __future__ import annotations

from kalcal.stats.distributions import chi2_isf, chi2_ppf, normal_isf

__all__ = [
    "COVARIANCE_PARTS",
    "WHITENESS_PARTS",
    "centered_nees_bounds",
    "chi2_bounds_at",
    "chi2_mean_bounds",
    "covariance_element_bound",
    "normal_bound",
    "normal_bound_at",
    "portmanteau_bound",
    "verdict_false_alarm_bound",
    "whiteness_pairs_bound",
]

#: the tests of the covariance check, each held to an equal share of its alpha
COVARIANCE_PARTS = ("elements", "centered_nees")
#: the tests of the residual whiteness check, each held to an equal share of its alpha
WHITENESS_PARTS = ("pairs", "portmanteau")


def normal_bound(confidence: float, comparisons: int) -> float:
    """Two-sided normal quantile for a family of ``comparisons`` at family-wise ``confidence``."""
    return normal_bound_at(1.0 - confidence, comparisons)


def chi2_mean_bounds(confidence: float, comparisons: int, dof: float, count: float) -> tuple[float, float]:
    """Bounds on the mean of ``count`` terms whose sum is chi-square with ``dof`` degrees of freedom."""
    return chi2_bounds_at(1.0 - confidence, comparisons, dof, count)


def normal_bound_at(alpha: float, comparisons: int) -> float:
    return float(normal_isf(alpha / (2.0 * comparisons)))


def chi2_bounds_at(alpha: float, comparisons: int, dof: float, count: float) -> tuple[float, float]:
    tail = alpha / (2.0 * comparisons)
    return float(chi2_ppf(tail, dof) / count), float(chi2_isf(tail, dof) / count)


def covariance_element_bound(confidence: float, n_updates: int, d: int) -> float:
    """The bound of the covariance check's element-wise part: K d (d + 1) / 2 comparisons at alpha / 2."""
    return normal_bound_at((1.0 - confidence) / len(COVARIANCE_PARTS), n_updates * d * (d + 1) // 2)


def whiteness_pairs_bound(confidence: float, n_updates: int, p: int) -> float:
    """The bound on |z| of the whiteness check's pairs part: max(1, p^2 K (K - 1) / 2) comparisons at alpha / 2."""
    comparisons = max(1, p * p * n_updates * (n_updates - 1) // 2)
    return normal_bound_at((1.0 - confidence) / len(WHITENESS_PARTS), comparisons)


def portmanteau_bound(alpha: float, dof: int) -> float:
    """The upper alpha quantile of chi-square(dof), the whiteness portmanteau's bound (0 for dof = 0)."""
    return float(chi2_isf(alpha, dof)) if dof else 0.0


def verdict_false_alarm_bound(confidence: float, checks: int) -> float:
    """Bound on the probability that a correct filter fails at least one of ``checks`` checks.

    min(1, checks * (1 - confidence)) (Bonferroni over the checks, each at ``confidence``).
    """
    return float(min(1.0, checks * (1.0 - confidence)))


def centered_nees_bounds(confidence: float, n_updates: int, d: int, count: int) -> tuple[float, float]:
    """Bounds of :func:`centered_nees` in the covariance check, whose confidence is ``confidence``.

    K = ``n_updates`` comparisons of N = ``count`` realizations at the part's share of alpha (alpha / 2,
    see :func:`kalcal.stats.covariance.check_covariance`)."""
    share = (1.0 - confidence) / len(COVARIANCE_PARTS)
    return chi2_bounds_at(share, n_updates, d * (count - 1), count - 1)
