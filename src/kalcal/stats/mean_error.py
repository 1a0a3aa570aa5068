"""The mean-error check: E[e_k] = 0 at every update and state, against t(N - 1), and its power.

Each state's mean error over its own standard error (from the ensemble variance) is t(N - 1) exactly where
every realization shares P_k; where P_k differs between realizations the whitened error eps_k = L_k^-1 e_k
is tested instead (:func:`check_mean_error`). The family of K d comparisons is held to alpha by
Bonferroni (:func:`~kalcal.stats.bounds.normal_bound`); :func:`mean_error_power` is its power under a
truth from the exact analysis.
"""

from __future__ import annotations

import numpy as np

from kalcal.analysis.fixed_gain import CovarianceAnalysis
from kalcal.montecarlo.accumulators import EnsembleStatistics
from kalcal.montecarlo.problem import ProblemInfo
from kalcal.stats.bounds import normal_bound
from kalcal.stats.covariance import t_equivalent_z, whitened_moments
from kalcal.stats.power import NormalFamily
from kalcal.stats.results import (
    Cause,
    CheckResult,
    check_result,
    failed_cause,
    max_abs,
    normal_family_pvalue,
    safe_ratio,
    sd_text,
    standardized,
    where_text,
    zero_se_text,
)

__all__ = ["check_mean_error", "mean_error_power"]


def check_mean_error(
    s: EnsembleStatistics,
    info: ProblemInfo,
    confidence: float,
    expected: np.ndarray | None = None,
    cause: str = "",
) -> CheckResult:
    """E[e_k] = 0 for every update and state.

    Where every realization shares P_k each state's error is iid N(0, P_ii) over the realizations, so
    its mean over its own standard error (from the ensemble variance) is t(N - 1) exactly. Where P_k
    differs between realizations (the whitened sums kept) the raw errors are not identically
    distributed and that ratio has no exact law (a scale mixture: conservative, so it loses power); the
    check then tests the whitened error eps_k = L_k^-1 e_k (each realization's own P_k), whose
    components are iid N(0, 1): the mean of each over its own standard error is t(N - 1) exactly.

    When it fails and ``expected`` (K, d) is the mean error the filter's model predicts against the truth,
    the failure is ``explained_by="model_error"`` if removing it leaves every deviation inside the bound.
    ``cause`` names what makes the truth depart from the filter's model, for the detail.
    """
    alpha = 1.0 - confidence
    n_updates, d = s.mean_error.shape
    m = n_updates * d
    bound = normal_bound(confidence, m)
    se = np.sqrt(np.maximum(np.diagonal(s.error_cov, axis1=1, axis2=2), 0.0) / s.count)
    whitened = s.mean_whitened_error is not None
    if whitened:  # P_k differs between realizations: the whitened errors, iid N(0, I) for a correct filter
        white = whitened_moments(s)
        tested = white.mean
        tested_se = np.sqrt(np.maximum(np.diagonal(white.cov, axis1=1, axis2=2), 0.0) / s.count)
    else:
        tested, tested_se = s.mean_error, se
    t, zero_pass, zero_fail = standardized(tested, tested_se)
    # mean / se of N normal errors (se from their sample variance) is t(N - 1) exactly, not N(0, 1): at
    # N = 100 the normal tail is about 3 times too light at 4.3 sigma, where a family of 450 reaches
    z = t_equivalent_z(t, s.count - 1)
    worst, (k, i) = max_abs(z)
    pvalue = normal_family_pvalue(worst, m)
    passed = pvalue >= alpha
    sigma = np.sqrt(np.diagonal(s.filter_cov, axis1=1, axis2=2))
    big, (kb, ib) = max_abs(safe_ratio(s.mean_error, sigma))
    what = "mean whitened error (eps = L^-1 e, each realization's own P)" if whitened else "mean error"
    detail = (
        f"largest |{what}| {sd_text(abs(t[k, i]))} standard errors, t({s.count - 1}), {sd_text(worst)} sd-equivalent "
        f"({where_text(info, k, info.state_names[i])}"
        + (f": {what} {tested[k, i]:.6g} with zero standard error" if np.isinf(worst) else "")
        + f"); largest in filter sigma {big:.2f} sigma ({where_text(info, kb, info.state_names[ib])})"
        + zero_se_text(zero_pass, zero_fail, "mean error")
    )
    diagnosis = Cause()
    if not passed and expected is not None and np.any(expected != 0):
        predicted, (kp, ip) = max_abs(safe_ratio(expected, sigma))
        # ``expected`` is in the states' units: removed from the raw mean error, over the raw standard error
        # (where P varies the raw ratio is conservative, so this explanation errs toward "does not explain")
        rest_t, _, _ = standardized(s.mean_error - expected, se)
        rest, _ = max_abs(t_equivalent_z(rest_t, s.count - 1))
        if normal_family_pvalue(rest, m) >= alpha:
            diagnosis = failed_cause(
                f"Explained by the predicted systematic error: {cause or 'the truth departs from the filter model'} "
                f"predicts a mean error of up to {predicted:.2f} sigma ({where_text(info, kp, info.state_names[ip])}); "
                f"after removing it the largest deviation is {rest:.2f} standard errors, within {bound:.2f}",
                explained_by="model_error",
            )
        else:
            diagnosis = failed_cause(
                f"The predicted systematic error ({cause or 'truth against filter model'}) reaches "
                f"{predicted:.2f} sigma but does not explain all of it ({sd_text(rest)} standard errors remain)"
            )
    elif not passed:
        diagnosis = failed_cause("The filter model predicts no mean error: its model or prior mean differs from the truth")
    return check_result("mean_error", worst, pvalue, None, bound, confidence, m, passed, detail, diagnosis)


def mean_error_power(a: CovarianceAnalysis, confidence: float) -> NormalFamily:
    """The check's family under the truth: each update's and state's mean error against its standard error
    (K d comparisons, a :class:`~kalcal.stats.power.NormalFamily`), from the exact moments of ``a``."""
    m = a.moments
    var = np.diagonal(m.error_cov, axis1=1, axis2=2)
    return NormalFamily(m.mean_error.ravel(), var.ravel(), var.ravel(), normal_bound(confidence, var.size))
