"""The orthogonality check: E[eps_k xhat_k^T] = 0, the whitened error uncorrelated with the estimate, and its power.

Given the N estimates, the uncentered correlation of eps_k,i with xhat_k,l is t(N - 1) exactly for a
correct filter (:func:`check_orthogonality`); the family of K d^2 comparisons is held to alpha by
Bonferroni. :func:`orthogonality_power` is its power under a truth from the exact analysis.
"""

from __future__ import annotations

import numpy as np

from kalcal.analysis.fixed_gain import CovarianceAnalysis
from kalcal.montecarlo.accumulators import EnsembleStatistics
from kalcal.montecarlo.problem import ProblemInfo
from kalcal.stats.bounds import normal_bound
from kalcal.stats.covariance import correlation_z, whitened_moments
from kalcal.stats.power import NormalFamily, product_variance
from kalcal.stats.results import (
    Cause,
    CheckResult,
    centered_cause,
    check_result,
    max_abs,
    normal_family_pvalue,
    sd_text,
    zero_se_text,
)

__all__ = ["check_orthogonality", "orthogonality_power"]


def check_orthogonality(s: EnsembleStatistics, info: ProblemInfo, confidence: float) -> CheckResult:
    """E[e_k xhat_k^T] = 0: the error is orthogonal to the estimate, tested on the whitened error.

    For a correct filter eps_k = L_k^-1 e_k (each realization's own P_k) is N(0, I) and independent of
    the estimate, so given the N estimates xhat_k,l the N values eps_k,i are iid N(0, 1) and the
    uncentered sample correlation r = sum eps_i xhat_l / sqrt(sum eps_i^2 sum xhat_l^2) has
    r sqrt(N - 1) / sqrt(1 - r^2) ~ t(N - 1) exactly, at every N. (The earlier z = sqrt(N) r against
    N(0, 1) was no exact law: a product of two normals has heavy tails.) The statistic is the largest of
    the K d^2 correlations' |z| (:func:`~kalcal.stats.covariance.correlation_z`: the |z| of the smallest
    two-sided p-value, finite also where it underflows).
    """
    alpha = 1.0 - confidence
    n_updates, d, _ = s.error_estimate.shape
    m = n_updates * d * d
    bound = normal_bound(confidence, m)
    white = whitened_moments(s)
    # an update whose P_k cannot whiten keeps the raw error (iid N(0, P_ii) there for fixed gains)
    raw = white.singular[:, None, None]
    moment = np.where(raw, s.error_estimate, white.estimate)
    e2 = np.where(raw[:, :, 0], np.diagonal(s.error_second_moment, axis1=1, axis2=2), np.diagonal(white.second, axis1=1, axis2=2))
    x2 = np.diagonal(s.estimate_second_moment, axis1=1, axis2=2)
    z, zero_pass, zero_fail = correlation_z(moment, e2[:, :, None] * x2[:, None, :], s.count - 1)
    worst, (k, i, l) = max_abs(z)
    pvalue = normal_family_pvalue(worst, m)
    passed = pvalue >= alpha
    with np.errstate(divide="ignore", invalid="ignore"):
        r = moment[k, i, l] / np.sqrt(e2[k, i] * x2[k, l])
    detail = (
        f"largest |E[eps xhat^T]| (eps = L^-1 e, whitened by P) {sd_text(worst)} sd-equivalent (eps_{info.state_names[i]} x "
        f"xhat_{info.state_names[l]} at t = {info.update_times[k]:g} s: correlation {r:.4f}, t({s.count - 1}))"
        + zero_se_text(zero_pass, zero_fail, "moment")
    )
    diagnosis = Cause()
    if not passed:
        centered = moment - np.where(raw[:, :, 0], s.mean_error, white.mean)[:, :, None] * s.mean_estimate[:, None, :]
        var_e = np.maximum(e2 - np.where(raw[:, :, 0], s.mean_error, white.mean) ** 2, 0.0)
        var_x = np.maximum(x2 - s.mean_estimate**2, 0.0)
        # the centered sample correlation of independent normal samples: t(N - 2)
        rest_z, _, _ = correlation_z(centered, var_e[:, :, None] * var_x[:, None, :], s.count - 2)
        diagnosis = centered_cause(
            rest_z,
            m,
            alpha,
            "the means",
            "the mean error accounts for it (see mean_error)",
            "error and estimate are correlated: the gains are not optimal for the truth",
        )
    return check_result("orthogonality", worst, pvalue, None, bound, confidence, m, passed, detail, diagnosis)


def orthogonality_power(a: CovarianceAnalysis, confidence: float) -> NormalFamily:
    """The check's family under the truth: each E[e_i xhat_l] against its standard error (K d^2
    comparisons, the variance of a product of jointly Gaussian terms), from the exact moments of ``a``."""
    m = a.moments
    if m.estimate_cov is None:
        raise ValueError("the analysis has no Cov(xhat): run it with kalcal.core.lincov.propagate")
    mu_e, mu_x = m.mean_error[:, :, None], m.mean_estimate[:, None, :]
    var_e = np.diagonal(m.error_cov, axis1=1, axis2=2)[:, :, None]
    var_x = np.diagonal(m.estimate_cov, axis1=1, axis2=2)[:, None, :]
    cov = m.error_estimate - mu_e * mu_x
    variance = product_variance(mu_e, mu_x, var_e, var_x, cov)
    scale = (var_e + mu_e**2) * (var_x + mu_x**2)
    return NormalFamily(m.error_estimate.ravel(), variance.ravel(), scale.ravel(), normal_bound(confidence, cov.size))
