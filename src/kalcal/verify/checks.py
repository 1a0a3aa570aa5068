"""Statistical checks of a filter against its Monte Carlo ensemble, each with computed bounds and a p-value.

Every check tests one property the theory promises for a correct filter, over all update times (and all
elements) at once: the family of comparisons is held to alpha = 1 - confidence by a Bonferroni
correction (alpha / m for m comparisons), so a correct filter fails a check with probability at most
alpha. The covariance check is made of two tests, each at alpha / 2. N realizations, K updates,
d states, p measurements.

==================== ===================================================== =====================================
check                statistic                                             bound
==================== ===================================================== =====================================
mean_error           max |mean(e) / se|, se = sqrt(ensemble var / N)       normal quantile, m = K d
covariance           max |ensemble cov - P| / sd, sd^2 = (P_il^2 +          at alpha / 2: normal quantile,
                     P_ii P_ll) / N; and mean centered NEES                 m = K d (d + 1) / 2; and at alpha / 2:
                                                                           chi-square(d (N - 1)) / (N - 1), m = K
orthogonality        max |mean(e x^T)| / sqrt(E[e^2] E[x^2] / N)            normal quantile, m = K d^2
residual_whiteness   max over j < k of |mean(r_k r_j^T)| /                  normal quantile, m = p^2 K (K - 1) / 2
                     sqrt(E[r_k^2] E[r_j^2] / N)
nis                  mean NIS at the update farthest from p                 chi-square(N p) / N, m = K
==================== ===================================================== =====================================

Each result carries its family-wise p-value (:mod:`kalcal.verify.results`), with
``passed == (pvalue >= 1 - confidence)``, and the cause of a failure as data (:class:`Cause`).

A comparison whose standard error is zero (no spread over the ensemble) passes when its value is
exactly zero and fails otherwise (its z is infinite: no spread cannot hide a nonzero mean); the detail
counts both kinds.

The covariance check compares the *centered* ensemble covariance, so that a mean error is reported once,
by ``mean_error``; orthogonality, whiteness and NIS use raw moments, as the source report does, and
when they fail their cause says whether the mean error accounts for it (the centered statistic passes).

The verdict is over the five checks: a correct filter passes every one with probability at least
1 - 5 alpha (Bonferroni over the checks; :func:`verdict_false_alarm_bound`).
"""

from __future__ import annotations

import numpy as np
from scipy import stats as sps

from kalcal.montecarlo.accumulators import EnsembleStatistics
from kalcal.montecarlo.problem import ProblemInfo
from kalcal.verify.results import (
    Cause,
    CheckPart,
    CheckResult,
    chi2_two_sided_pvalues,
    combined_pvalue,
    family_pvalue,
    normal_family_pvalue,
    with_reason,
)

__all__ = [
    "DEFAULT_CONFIDENCE",
    "REPORT_RESIDUAL_PAIR",
    "Cause",
    "CheckPart",
    "CheckResult",
    "check_covariance",
    "check_mean_error",
    "check_nis",
    "check_orthogonality",
    "check_residual_whiteness",
    "chi2_mean_bounds",
    "covariance_element_bound",
    "normal_bound",
    "residual_pair",
    "run_checks",
    "verdict",
    "verdict_false_alarm_bound",
]

DEFAULT_CONFIDENCE = 0.99
#: where the source report quotes E[r_k r_j^T]
REPORT_RESIDUAL_PAIR = (23.8, 5.8)
#: the tests of the covariance check, each held to an equal share of its alpha
COVARIANCE_PARTS = ("elements", "centered_nees")


def normal_bound(confidence: float, comparisons: int) -> float:
    """Two-sided normal quantile for a family of ``comparisons`` at family-wise ``confidence``."""
    return _normal_bound(1.0 - confidence, comparisons)


def chi2_mean_bounds(confidence: float, comparisons: int, dof: float, count: float) -> tuple[float, float]:
    """Bounds on the mean of ``count`` terms whose sum is chi-square with ``dof`` degrees of freedom."""
    return _chi2_bounds(1.0 - confidence, comparisons, dof, count)


def _normal_bound(alpha: float, comparisons: int) -> float:
    return float(sps.norm.isf(alpha / (2.0 * comparisons)))


def _chi2_bounds(alpha: float, comparisons: int, dof: float, count: float) -> tuple[float, float]:
    tail = alpha / (2.0 * comparisons)
    return float(sps.chi2.ppf(tail, dof) / count), float(sps.chi2.isf(tail, dof) / count)


def covariance_element_bound(confidence: float, n_updates: int, d: int) -> float:
    """The bound of the covariance check's element-wise part: K d (d + 1) / 2 comparisons at alpha / 2."""
    return _normal_bound((1.0 - confidence) / len(COVARIANCE_PARTS), n_updates * d * (d + 1) // 2)


def verdict_false_alarm_bound(confidence: float, checks: int) -> float:
    """Bound on the probability that a correct filter fails at least one of ``checks`` checks.

    min(1, checks * (1 - confidence)) (Bonferroni over the checks, each at ``confidence``).
    """
    return float(min(1.0, checks * (1.0 - confidence)))


def _where(info: ProblemInfo, k: int, *names: str) -> str:
    return f"{'/'.join(names)} at t = {info.update_times[k]:g} s"


def _max_abs(z: np.ndarray) -> tuple[float, tuple[int, ...]]:
    index = np.unravel_index(int(np.argmax(np.abs(z))), z.shape)
    return float(np.abs(z[index])), tuple(int(i) for i in index)


def _safe_ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    """num / den, 0 where den is not positive: for display only, never for a test."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)


def _standardized(num: np.ndarray, se: np.ndarray, mask: np.ndarray | None = None) -> tuple[np.ndarray, int, int]:
    """z = num / se, where a zero standard error gives z = 0 for an exactly zero num and +-inf otherwise.

    Returns z (masked entries set to 0), and how many comparisons (within ``mask``) had zero standard
    error with a zero value (passing) and with a nonzero value (failing).
    """
    num, se = np.broadcast_arrays(np.asarray(num, dtype=float), np.asarray(se, dtype=float))
    keep = np.ones(num.shape, dtype=bool) if mask is None else np.broadcast_to(mask, num.shape)
    zero = (se == 0) & keep
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(zero, np.where(num == 0, 0.0, np.copysign(np.inf, num)), num / np.where(zero, 1.0, se))
    z = np.where(keep, z, 0.0)
    return z, int(np.count_nonzero(zero & (num == 0))), int(np.count_nonzero(zero & (num != 0)))


def _zero_se_text(passing: int, failing: int, what: str) -> str:
    """The detail's account of the comparisons that had zero standard error."""
    texts = []
    if passing:
        texts.append(f"{passing} comparison(s) with zero standard error and an exactly zero {what}, counted as passed")
    if failing:
        texts.append(
            f"{failing} comparison(s) with zero standard error and a nonzero {what}, counted as failed (no spread "
            "over the ensemble cannot account for a nonzero value)"
        )
    return "".join(f"; {text}" for text in texts)


def _sd_text(value: float) -> str:
    return "inf" if np.isinf(value) else f"{value:.2f}"


def _failed(reason: str, explained_by: str | None = None, direction: str | None = None) -> Cause:
    return Cause(explained_by=explained_by, direction=direction, reason=reason)


def _centered_cause(rest_z: np.ndarray, m: int, alpha: float, on: str, explained: str, otherwise: str) -> Cause:
    """The cause of a failed raw-moment check, from its z-statistics ``rest_z`` recentred on ``on``: the
    mean error when the recentred family of ``m`` comparisons passes at ``alpha``, else ``otherwise``."""
    rest, _ = _max_abs(rest_z)
    lead = f"Centered on {on} the largest is {_sd_text(rest)}: "
    if normal_family_pvalue(rest, m) >= alpha:
        return _failed(lead + explained, explained_by="mean_error")
    return _failed(lead + otherwise)


def _result(
    name: str,
    statistic: float,
    pvalue: float,
    lower: float | None,
    upper: float | None,
    confidence: float,
    comparisons: int,
    passed: bool,
    measured: str,
    cause: Cause,
    parts: tuple = (),
) -> CheckResult:
    """A check's result, its ``detail`` the measured text followed by the cause's reason."""
    return CheckResult(
        name=name,
        statistic=statistic,
        pvalue=pvalue,
        lower=lower,
        upper=upper,
        confidence=confidence,
        comparisons=comparisons,
        passed=passed,
        detail=with_reason(measured, cause),
        measured=measured,
        cause=cause,
        parts=parts,
    )




def check_mean_error(
    s: EnsembleStatistics,
    info: ProblemInfo,
    confidence: float,
    expected: np.ndarray | None = None,
    cause: str = "",
) -> CheckResult:
    """E[e_k] = 0 for every update and state.

    When it fails and ``expected`` (K, d) is the mean error the filter's model predicts against the truth,
    the failure is ``explained_by="model_error"`` if removing it leaves every deviation inside the bound.
    ``cause`` names what makes the truth depart from the filter's model, for the detail.
    """
    alpha = 1.0 - confidence
    n_updates, d = s.mean_error.shape
    m = n_updates * d
    bound = normal_bound(confidence, m)
    se = np.sqrt(np.maximum(np.diagonal(s.error_cov, axis1=1, axis2=2), 0.0) / s.count)
    z, zero_pass, zero_fail = _standardized(s.mean_error, se)
    worst, (k, i) = _max_abs(z)
    pvalue = normal_family_pvalue(worst, m)
    passed = pvalue >= alpha
    sigma = np.sqrt(np.diagonal(s.filter_cov, axis1=1, axis2=2))
    big, (kb, ib) = _max_abs(_safe_ratio(s.mean_error, sigma))
    detail = (
        f"largest |mean error| {_sd_text(worst)} standard errors ({_where(info, k, info.state_names[i])}"
        + (f": mean error {s.mean_error[k, i]:.6g} with zero standard error" if np.isinf(worst) else "")
        + f"); largest in filter sigma {big:.2f} sigma ({_where(info, kb, info.state_names[ib])})"
        + _zero_se_text(zero_pass, zero_fail, "mean error")
    )
    diagnosis = Cause()
    if not passed and expected is not None and np.any(expected != 0):
        predicted, (kp, ip) = _max_abs(_safe_ratio(expected, sigma))
        rest_z, _, _ = _standardized(s.mean_error - expected, se)
        rest, _ = _max_abs(rest_z)
        if normal_family_pvalue(rest, m) >= alpha:
            diagnosis = _failed(
                f"Explained by the predicted systematic error: {cause or 'the truth departs from the filter model'} "
                f"predicts a mean error of up to {predicted:.2f} sigma ({_where(info, kp, info.state_names[ip])}); "
                f"after removing it the largest deviation is {rest:.2f} standard errors, within {bound:.2f}",
                explained_by="model_error",
            )
        else:
            diagnosis = _failed(
                f"The predicted systematic error ({cause or 'truth against filter model'}) reaches "
                f"{predicted:.2f} sigma but does not explain all of it ({_sd_text(rest)} standard errors remain)"
            )
    elif not passed:
        diagnosis = _failed("The filter model predicts no mean error: its model or prior mean differs from the truth")
    return _result("mean_error", worst, pvalue, None, bound, confidence, m, passed, detail, diagnosis)


def centered_nees(error_cov: np.ndarray, filter_cov: np.ndarray) -> np.ndarray:
    """Centered mean NEES tr(P_k^-1 C_k), (K,), from the ensemble covariance C of e (K, d, d) and P (K, d, d).

    For a consistent filter (N - 1) times it is chi-square with d (N - 1) degrees of freedom (the mean
    error taken out, so a mean error does not lift it)."""
    return np.trace(np.linalg.solve(filter_cov, error_cov), axis1=1, axis2=2)


def centered_nees_bounds(confidence: float, n_updates: int, d: int, count: int) -> tuple[float, float]:
    """Bounds of :func:`centered_nees` in the covariance check, whose confidence is ``confidence``.

    K = ``n_updates`` comparisons of N = ``count`` realizations at the part's share of alpha (alpha / 2,
    see :func:`check_covariance`)."""
    share = (1.0 - confidence) / len(COVARIANCE_PARTS)
    return _chi2_bounds(share, n_updates, d * (count - 1), count - 1)


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
    z_full, _, _ = _standardized(deviation, sd)
    z, zero_pass, zero_fail = _standardized(deviation[:, upper[0], upper[1]], sd[:, upper[0], upper[1]])
    worst, (k, e) = _max_abs(z)
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
    ratio = _safe_ratio(np.diagonal(s.error_cov, axis1=1, axis2=2), diag)
    detail = (
        f"largest deviation {_sd_text(worst)} sd in element ({info.state_names[i]}, {info.state_names[l]}) at "
        f"t = {info.update_times[k]:g} s, bound {bound:.2f} (at alpha / 2 = {share:.3g}); ensemble/filter variance "
        f"ratio from {ratio.min():.3f} to {ratio.max():.3f}; centered mean NEES from {nees_values.min():.4f} to "
        f"{nees_values.max():.4f}, bounds [{low:.4f}, {high:.4f}] (at alpha / 2)"
        + _zero_se_text(zero_pass, zero_fail, "deviation")
    )
    diagnosis = Cause()
    if not passed:
        diagnosis = _covariance_cause(z_full, _element_pvalues(z_full, m) < share, nees, info, (k, i, l))
    return _result(
        "covariance", worst, pvalue, None, bound, confidence, m + n_updates, passed, detail, diagnosis, parts=parts
    )


def _element_pvalues(z: np.ndarray, comparisons: int) -> np.ndarray:
    """Bonferroni p-value of each element's |z| in a family of ``comparisons`` (as the elements part's)."""
    return np.minimum(1.0, comparisons * 2.0 * sps.norm.sf(np.abs(z)))


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
            return _failed(
                f"The ensemble variance of {', '.join(over)} exceeds P's and that of {', '.join(under)} falls short "
                "of it: no single direction (the noise settings are wrong in opposite ways)"
            )
        overconfident = signs == {1.0}
    elif not nees.passed:
        overconfident = nees.statistic > nees.upper
    else:
        k, i, l = worst
        return _failed(
            f"The correlation of {info.state_names[i]} and {info.state_names[l]} differs from P's (the variances "
            f"agree; largest at t = {info.update_times[k]:g} s): the filter's model couples the states differently "
            "from the truth"
        )
    if overconfident:
        return _failed(
            "The filter is overconfident: its P is smaller than the actual spread (noise settings too small)",
            direction="overconfident",
        )
    return _failed(
        "The filter is underconfident: its P is larger than the actual spread (noise settings too large)",
        direction="underconfident",
    )


def check_orthogonality(s: EnsembleStatistics, info: ProblemInfo, confidence: float) -> CheckResult:
    """E[e_k xhat_k^T] = 0: the error is orthogonal to the estimate."""
    alpha = 1.0 - confidence
    n_updates, d, _ = s.error_estimate.shape
    m = n_updates * d * d
    bound = normal_bound(confidence, m)
    e2 = np.diagonal(s.error_second_moment, axis1=1, axis2=2)
    x2 = np.diagonal(s.estimate_second_moment, axis1=1, axis2=2)
    z, zero_pass, zero_fail = _standardized(s.error_estimate, np.sqrt(e2[:, :, None] * x2[:, None, :] / s.count))
    worst, (k, i, l) = _max_abs(z)
    pvalue = normal_family_pvalue(worst, m)
    passed = pvalue >= alpha
    detail = (
        f"largest |E[e xhat^T]| {_sd_text(worst)} standard errors (e_{info.state_names[i]} x "
        f"xhat_{info.state_names[l]} at t = {info.update_times[k]:g} s)" + _zero_se_text(zero_pass, zero_fail, "moment")
    )
    diagnosis = Cause()
    if not passed:
        centered = s.error_estimate - s.mean_error[:, :, None] * s.mean_estimate[:, None, :]
        var_e = np.maximum(np.diagonal(s.error_cov, axis1=1, axis2=2), 0.0)
        var_x = np.maximum(x2 - s.mean_estimate**2, 0.0)
        rest_z, _, _ = _standardized(centered, np.sqrt(var_e[:, :, None] * var_x[:, None, :] / s.count))
        diagnosis = _centered_cause(
            rest_z,
            m,
            alpha,
            "the means",
            "the mean error accounts for it (see mean_error)",
            "error and estimate are correlated: the gains are not optimal for the truth",
        )
    return _result("orthogonality", worst, pvalue, None, bound, confidence, m, passed, detail, diagnosis)


def residual_pair(s: EnsembleStatistics, info: ProblemInfo, t_k: float, t_j: float) -> dict:
    """E[r_k r_j^T] at the updates nearest to t_k and t_j (the report quotes k = 23.8 s, j = 5.8 s)."""
    times = info.update_times
    k = int(np.argmin(np.abs(times - t_k)))
    j = int(np.argmin(np.abs(times - t_j)))
    moment = s.residual_second_moment
    scale = np.sqrt(np.outer(np.diagonal(moment[k, :, k, :]), np.diagonal(moment[j, :, j, :])))
    return {
        "k_time": float(times[k]),
        "j_time": float(times[j]),
        "matrix": moment[k, :, j, :],
        "correlation": _safe_ratio(moment[k, :, j, :], scale),
        "standard_error": scale / np.sqrt(s.count),
    }


def check_residual_whiteness(s: EnsembleStatistics, info: ProblemInfo, confidence: float) -> CheckResult:
    """E[r_k r_j^T] = 0 for every j < k: the innovations are white."""
    alpha = 1.0 - confidence
    moment = s.residual_second_moment  # (K, p, K, p)
    n_updates, p = moment.shape[:2]
    pairs = n_updates * (n_updates - 1) // 2
    m = max(1, p * p * pairs)
    bound = normal_bound(confidence, m)
    power = np.diagonal(moment.reshape(n_updates * p, n_updates * p)).reshape(n_updates, p)
    scale = np.sqrt(np.einsum("ka,jb->kajb", power, power) / s.count)
    lower = np.tril(np.ones((n_updates, n_updates), dtype=bool), -1)[:, None, :, None]  # j < k
    z, zero_pass, zero_fail = _standardized(moment, scale, lower)
    worst, (k, a, j, b) = _max_abs(z)
    pvalue = normal_family_pvalue(worst, m)
    passed = pvalue >= alpha
    detail = (
        f"largest |E[r_k r_j^T]| {_sd_text(worst)} standard errors ({info.measurement_names[a]} at "
        f"t = {info.update_times[k]:g} s with {info.measurement_names[b]} at t = {info.update_times[j]:g} s) over "
        f"{pairs} pairs of updates" + _zero_se_text(zero_pass, zero_fail, "moment")
    )
    diagnosis = Cause()
    if not passed:
        mean = s.mean_residual
        centered = moment - np.einsum("ka,jb->kajb", mean, mean)
        var = np.maximum(power - mean**2, 0.0)
        rest_z, _, _ = _standardized(centered, np.sqrt(np.einsum("ka,jb->kajb", var, var) / s.count), lower)
        diagnosis = _centered_cause(
            rest_z,
            m,
            alpha,
            "the residual means",
            "nonzero mean residuals account for it (see mean_error)",
            "the innovations are correlated in time: the model's dynamics or noise are wrong",
        )
    return _result("residual_whiteness", worst, pvalue, None, bound, confidence, m, passed, detail, diagnosis)


def check_nis(s: EnsembleStatistics, info: ProblemInfo, confidence: float) -> CheckResult:
    """Mean NIS at each update within its chi-square(N p) / N bounds.

    The statistic is the mean NIS at the update with the smallest two-sided p-value. A failure is
    ``explained_by="mean_error"`` when the mean NIS centered on the mean normalized innovations lies
    within the bounds; otherwise its direction is ``"overconfident"`` (innovations larger than the
    filter's S) or ``"underconfident"``.
    """
    alpha = 1.0 - confidence
    n_updates, p = s.mean_residual.shape
    low, high = chi2_mean_bounds(confidence, n_updates, p * s.count, s.count)
    per_update = chi2_two_sided_pvalues(s.mean_nis, p * s.count, s.count)
    k = int(np.nanargmin(per_update)) if not np.all(np.isnan(per_update)) else 0
    worst = float(s.mean_nis[k])
    pvalue = family_pvalue(per_update)
    passed = pvalue >= alpha
    detail = (
        f"mean NIS from {s.mean_nis.min():.4f} to {s.mean_nis.max():.4f} (expected {p}); farthest at "
        f"t = {info.update_times[k]:g} s"
    )
    diagnosis = Cause()
    if not passed:
        centered = None
        if s.mean_normalized_residual is not None:
            # E|nu - E nu|^2 = E|nu|^2 - |E nu|^2 for the normalized innovations nu = L^{-1} r
            centered = s.mean_nis - np.sum(s.mean_normalized_residual**2, axis=1)
        if centered is not None and np.all((centered >= low) & (centered <= high)):
            diagnosis = _failed(
                f"Centered on the mean innovations the mean NIS lies within the bounds "
                f"({centered.min():.4f} to {centered.max():.4f}): the nonzero mean residuals account for it "
                "(see mean_error)",
                explained_by="mean_error",
            )
        elif worst > p:
            diagnosis = _failed(
                "Innovations larger than the filter's S: the noise settings are too small", direction="overconfident"
            )
        else:
            diagnosis = _failed(
                "Innovations smaller than the filter's S: the noise settings are too large", direction="underconfident"
            )
    return _result("nis", worst, pvalue, low, high, confidence, n_updates, passed, detail, diagnosis)


def run_checks(
    s: EnsembleStatistics,
    info: ProblemInfo,
    confidence: float = DEFAULT_CONFIDENCE,
    expected_mean_error: np.ndarray | None = None,
    model_error_cause: str = "",
) -> list[CheckResult]:
    """Every check, in a fixed order."""
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence!r}")
    return [
        check_mean_error(s, info, confidence, expected_mean_error, model_error_cause),
        check_covariance(s, info, confidence),
        check_orthogonality(s, info, confidence),
        check_residual_whiteness(s, info, confidence),
        check_nis(s, info, confidence),
    ]


def verdict(checks: list[CheckResult]) -> str:
    """``"pass"`` when every check passed, else ``"fail"``."""
    return "pass" if all(c.passed for c in checks) else "fail"
