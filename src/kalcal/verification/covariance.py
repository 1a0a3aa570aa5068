"""The covariance check: the ensemble covariance of the error against the filter's P, and the cause of a failure."""

from __future__ import annotations

import numpy as np

from kalcal.montecarlo.accumulators import EnsembleStatistics
from kalcal.montecarlo.problem import ProblemInfo
from kalcal.verification.bounds import COVARIANCE_PARTS, centered_nees_bounds, covariance_element_bound
from kalcal.verification.check_steps import check_result, failed_cause, max_abs, safe_ratio, sd_text, standardized, zero_se_text
from kalcal.verification.distributions import normal_sf
from kalcal.verification.results import (
    Cause,
    CheckPart,
    CheckResult,
    chi2_two_sided_pvalues,
    combined_pvalue,
    family_pvalue,
    normal_family_pvalue,
)

__all__ = ["centered_nees", "check_covariance"]


def centered_nees(error_cov: np.ndarray, filter_cov: np.ndarray) -> np.ndarray:
    """Centered mean NEES tr(P_k^-1 C_k), (K,), from the ensemble covariance C of e (K, d, d) and P (K, d, d).

    For a consistent filter (N - 1) times it is chi-square with d (N - 1) degrees of freedom (the mean
    error taken out, so a mean error does not lift it)."""
    return np.trace(np.linalg.solve(filter_cov, error_cov), axis1=1, axis2=2)


def check_covariance(s: EnsembleStatistics, info: ProblemInfo, confidence: float) -> CheckResult:
    """Ensemble covariance of e equals the filter's P, element by element and through the centered NEES.

    Two parts, each at half the check's alpha, so that the check's false-alarm rate is at most alpha:

    * ``elements``: max over k, i <= l of |C_k,il - P_k,il| / sd, sd^2 = (P_il^2 + P_ii P_ll) / N (C the
      centered ensemble covariance, divisor N - 1), normal quantile for K d (d + 1) / 2 comparisons;
    * ``centered_nees``: tr(P_k^{-1} C_k), whose (N - 1) multiple is chi-square(d (N - 1)) for a correct
      filter (Wishart), two-sided for K comparisons.

    The headline statistic and bounds are the element-wise part's. The direction of a failure is stated
    only where the data say it: the sign of the diagonal deviations outside the element-wise bound
    (C_ii > P_ii: overconfident; none if they disagree), else the side the centered NEES left its bounds
    on when that part failed; a failure of off-diagonal elements alone has no direction (the
    correlations differ, the variances agree).
    """
    alpha = 1.0 - confidence
    share = alpha / len(COVARIANCE_PARTS)
    n_updates, d, _ = s.filter_cov.shape
    upper = np.triu_indices(d)
    m = n_updates * upper[0].size
    bound = covariance_element_bound(confidence, n_updates, d)
    p = s.filter_cov
    diag = np.diagonal(p, axis1=1, axis2=2)
    sd = np.sqrt((p**2 + diag[:, :, None] * diag[:, None, :]) / s.count)
    deviation = s.error_cov - p
    z_full, _, _ = standardized(deviation, sd)
    z, zero_pass, zero_fail = standardized(deviation[:, upper[0], upper[1]], sd[:, upper[0], upper[1]])
    worst, (k, e) = max_abs(z)
    i, l = int(upper[0][e]), int(upper[1][e])
    p_elements = normal_family_pvalue(worst, m)
    elements = CheckPart(
        name="elements",
        statistic=worst,
        pvalue=p_elements,
        lower=None,
        upper=bound,
        confidence=1.0 - share,
        alpha=share,
        comparisons=m,
        passed=p_elements >= share,
    )
    nees_values = centered_nees(s.error_cov, p)
    dof = d * (s.count - 1)
    low, high = centered_nees_bounds(confidence, n_updates, d, s.count)
    nees_p = chi2_two_sided_pvalues(nees_values, dof, s.count - 1)
    kn = int(np.nanargmin(nees_p)) if not np.all(np.isnan(nees_p)) else 0
    p_nees = family_pvalue(nees_p)
    nees = CheckPart(
        name="centered_nees",
        statistic=float(nees_values[kn]),
        pvalue=p_nees,
        lower=low,
        upper=high,
        confidence=1.0 - share,
        alpha=share,
        comparisons=n_updates,
        passed=p_nees >= share,
    )
    parts = (elements, nees)
    pvalue = combined_pvalue(parts)
    passed = pvalue >= alpha
    ratio = safe_ratio(np.diagonal(s.error_cov, axis1=1, axis2=2), diag)
    detail = (
        f"largest deviation {sd_text(worst)} sd in element ({info.state_names[i]}, {info.state_names[l]}) at "
        f"t = {info.update_times[k]:g} s, bound {bound:.2f} (at alpha / 2 = {share:.3g}); ensemble/filter variance "
        f"ratio from {ratio.min():.3f} to {ratio.max():.3f}; centered mean NEES from {nees_values.min():.4f} to "
        f"{nees_values.max():.4f}, bounds [{low:.4f}, {high:.4f}] (at alpha / 2)"
        + zero_se_text(zero_pass, zero_fail, "deviation")
    )
    diagnosis = Cause()
    if not passed:
        diagnosis = _covariance_cause(z_full, _element_pvalues(z_full, m) < share, nees, info, (k, i, l))
    return check_result(
        "covariance", worst, pvalue, None, bound, confidence, m + n_updates, passed, detail, diagnosis, parts=parts
    )


def _element_pvalues(z: np.ndarray, comparisons: int) -> np.ndarray:
    """Bonferroni p-value of each element's |z| in a family of ``comparisons`` (as the elements part's)."""
    return np.minimum(1.0, comparisons * 2.0 * normal_sf(np.abs(z)))


def _covariance_cause(
    z: np.ndarray, failing: np.ndarray, nees: CheckPart, info: ProblemInfo, worst: tuple[int, int, int]
) -> Cause:
    """The direction of a failed covariance check, stated only where the data say it.

    ``z`` (K, d, d) are the element-wise deviations in sd and ``failing`` marks those outside the
    element-wise bound. A diagonal element outside the bound gives the direction by its sign (C_ii > P_ii:
    overconfident); failing diagonals of both signs give none. With no diagonal outside the bound, the
    centered NEES gives it when that part failed (above its bounds: overconfident); otherwise the failure
    is in an off-diagonal element alone (``worst`` = (k, i, l)): the correlation differs, the variances
    agree, and the direction is None.
    """
    z_diag = np.diagonal(z, axis1=1, axis2=2)
    out = np.diagonal(failing, axis1=1, axis2=2)
    if out.any():
        signs = set(np.sign(z_diag[out]).tolist())
        if len(signs) > 1:
            over = sorted({info.state_names[i] for i in np.nonzero(out & (z_diag > 0))[1]})
            under = sorted({info.state_names[i] for i in np.nonzero(out & (z_diag < 0))[1]})
            return failed_cause(
                f"The ensemble variance of {', '.join(over)} exceeds P's and that of {', '.join(under)} falls short "
                "of it: no single direction (the noise settings are wrong in opposite ways)"
            )
        overconfident = signs == {1.0}
    elif not nees.passed:
        overconfident = nees.statistic > nees.upper
    else:
        k, i, l = worst
        return failed_cause(
            f"The correlation of {info.state_names[i]} and {info.state_names[l]} differs from P's (the variances "
            f"agree; largest at t = {info.update_times[k]:g} s): the filter's model couples the states differently "
            "from the truth"
        )
    if overconfident:
        return failed_cause(
            "The filter is overconfident: its P is smaller than the actual spread (noise settings too small)",
            direction="overconfident",
        )
    return failed_cause(
        "The filter is underconfident: its P is larger than the actual spread (noise settings too large)",
        direction="underconfident",
    )
