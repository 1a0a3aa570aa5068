"""Statistical checks of a filter against its Monte Carlo ensemble, each with computed bounds and a p-value.

Every check tests one property the theory promises for a correct filter, over all update times (and all
elements) at once: the family of comparisons is held to alpha = 1 - confidence by a Bonferroni
correction (alpha / m for m comparisons), so a correct filter fails a check with probability at most
alpha, at every N: each comparison is held against its exact law under the null (chi-square, Student
t), never a normal approximation. The covariance and residual whiteness checks are each made of two
tests, each at alpha / 2. N realizations, K updates, d states, p measurements; eps_k = L_k^-1 e_k is the
error whitened by the filter's own P_k = L_k L_k^T (each realization by its own where P varies).

==================== ===================================================== =====================================
check                statistic                                             bound
==================== ===================================================== =====================================
mean_error           max |mean(e) / se|, se = sqrt(ensemble var / N); of    t(N - 1), m = K d
                     eps where P varies between realizations
covariance           whitened covariance W_k of eps_k: (N - 1) W_ii and    at alpha / 2: chi-square(N - 1) and
                     the correlations r_il, t = r sqrt(N - 2) /            t(N - 2), m = K d (d + 1) / 2; and
                     sqrt(1 - r^2); and the centered NEES tr(W_k)          at alpha / 2: chi-square(d (N - 1)) /
                                                                           (N - 1), m = K
orthogonality        max correlation of eps_i with xhat_l (uncentered),    t(N - 1), m = K d^2
                     t = r sqrt(N - 1) / sqrt(1 - r^2)
residual_whiteness   max over j < k of the correlation of r_k with r_j     at alpha / 2: t(N - 1),
                     (uncentered, as a t); and the portmanteau             m = p^2 K (K - 1) / 2; and at alpha / 2:
                     N sum_{j<k} ||S_k^-1/2 mean(r_k r_j^T) S_j^-T/2||^2  chi-square(p^2 K (K - 1) / 2), m = 1
nis                  mean NIS at the update farthest from p                 chi-square(N p) / N, m = K
==================== ===================================================== =====================================

Each t or chi-square comparison's two-sided p-value is shown as the normal |z| with that p-value, so
that a family's statistic stands against its normal Bonferroni bound. Measured on exact draws of a
correct filter's moments (20,000 ensembles each, confidence 0.99, K = 150 and d = 3 for the state
checks, K = 100 scalar innovations for whiteness and nis; tests/stats/test_false_alarm_rates.py):

====================== ============ ============ ===========
check / part           share        N = 100      N = 400
====================== ============ ============ ===========
mean_error             1%           170 (0.85%)  180 (0.90%)
covariance             1%           204 (1.02%)  175 (0.88%)
cov.elements           0.5%         101 (0.51%)  90 (0.45%)
cov.centered_nees      0.5%         110 (0.55%)  85 (0.43%)
orthogonality          1%           182 (0.91%)  162 (0.81%)
residual_whiteness     1%           186 (0.93%)  191 (0.96%)
whiteness.pairs        0.5%         98 (0.49%)   101 (0.51%)
whiteness.portmanteau  0.5%         88 (0.44%)   91 (0.46%)
nis                    1%           171 (0.86%)  200 (1.00%)
====================== ============ ============ ===========

Each result carries its family-wise p-value (:mod:`kalcal.stats.results`; the bounds: :mod:`kalcal.stats.bounds`), with
``passed == (pvalue >= 1 - confidence)``, and the cause of a failure as data (:class:`Cause`).

A comparison whose standard error is zero (no spread over the ensemble) passes when its value is
exactly zero and fails otherwise (its z is infinite: no spread cannot hide a nonzero mean); the detail
counts both kinds.

The residual whiteness check (:mod:`kalcal.stats.whiteness`) whitens each update's innovations with
their ensemble second moment S_k. The covariance check (:mod:`kalcal.stats.covariance`) compares the *centered* ensemble covariance, so that a mean error is reported once,
by ``mean_error``; orthogonality, whiteness and NIS use raw moments, as the source report does, and
when they fail their cause says whether the mean error accounts for it (the centered statistic passes).

The verdict is over the five checks: a correct filter passes every one with probability at least
1 - 5 alpha (Bonferroni over the checks; :func:`verdict_false_alarm_bound`).
"""

from __future__ import annotations

import numpy as np

from kalcal.analysis.fixed_gain import CovarianceAnalysis
from kalcal.linalg import whitener
from kalcal.montecarlo.accumulators import EnsembleStatistics
from kalcal.montecarlo.problem import ProblemInfo
from kalcal.stats.bounds import chi2_mean_bounds, normal_bound
from kalcal.stats.check_steps import (
    centered_cause,
    check_result,
    failed_cause,
    max_abs,
    safe_ratio,
    sd_text,
    standardized,
    where_text,
    zero_se_text,
)
from kalcal.stats.covariance import check_covariance, correlation_z, covariance_power, t_equivalent_z, whitened_moments
from kalcal.stats.power import ChiSquareFamily, CheckPower, NormalFamily, detection_n, power_row, product_variance
from kalcal.stats.whiteness import check_residual_whiteness, whiteness_power
from kalcal.stats.results import (
    Cause,
    CheckPart,
    CheckResult,
    chi2_two_sided_pvalues,
    family_pvalue,
    normal_family_pvalue,
)

__all__ = [
    "DEFAULT_CONFIDENCE",
    "REPORT_RESIDUAL_PAIR",
    "Cause",
    "CheckPart",
    "CheckResult",
    "check_mean_error",
    "check_nis",
    "check_families",
    "check_orthogonality",
    "mean_error_power",
    "nis_power",
    "orthogonality_power",
    "power_rows",
    "problem_power",
    "residual_pair",
    "run_checks",
    "verdict",
]

DEFAULT_CONFIDENCE = 0.99
#: where the source report quotes E[r_k r_j^T]
REPORT_RESIDUAL_PAIR = (23.8, 5.8)


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
        "correlation": safe_ratio(moment[k, :, j, :], scale),
        "standard_error": scale / np.sqrt(s.count),
    }


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
            diagnosis = failed_cause(
                f"Centered on the mean innovations the mean NIS lies within the bounds "
                f"({centered.min():.4f} to {centered.max():.4f}): the nonzero mean residuals account for it "
                "(see mean_error)",
                explained_by="mean_error",
            )
        elif worst > p:
            diagnosis = failed_cause(
                "Innovations larger than the filter's S: the noise settings are too small", direction="overconfident"
            )
        else:
            diagnosis = failed_cause(
                "Innovations smaller than the filter's S: the noise settings are too large", direction="underconfident"
            )
    return check_result("nis", worst, pvalue, low, high, confidence, n_updates, passed, detail, diagnosis)


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


def mean_error_power(a: CovarianceAnalysis, confidence: float) -> NormalFamily:
    m = a.moments
    var = np.diagonal(m.error_cov, axis1=1, axis2=2)
    return NormalFamily(m.mean_error.ravel(), var.ravel(), var.ravel(), normal_bound(confidence, var.size))


def orthogonality_power(a: CovarianceAnalysis, confidence: float) -> NormalFamily:
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


def nis_power(a: CovarianceAnalysis, confidence: float) -> ChiSquareFamily:
    m = a.moments
    n_updates, p = m.mean_residual.shape
    w = whitener(a.innovation_cov)
    ratio = w @ m.residual_cov @ np.swapaxes(w, 1, 2)  # A = S^-1/2 C S^-T/2
    mu = np.einsum("kab,kb->ka", w, m.mean_residual)

    def bounds(n: int) -> tuple[float, float]:
        low, high = chi2_mean_bounds(confidence, n_updates, p * n, n)
        return low * n, high * n

    return ChiSquareFamily(
        np.trace(ratio, axis1=1, axis2=2),
        np.einsum("kij,kji->k", ratio, ratio),
        np.sum(mu**2, axis=1),
        np.einsum("ka,kab,kb->k", mu, ratio, mu),
        0,
        bounds,
    )


def check_families(a: CovarianceAnalysis, confidence: float = 0.99) -> list[CheckPower]:
    """The five checks' families, in :func:`~kalcal.stats.checks.run_checks`' order (the
    whiteness check only where the analysis has the pair moments E[r_k r_j^T])."""
    checks = [
        CheckPower("mean_error", {None: mean_error_power(a, confidence)}),
        CheckPower("covariance", covariance_power(a, confidence)),
        CheckPower("orthogonality", {None: orthogonality_power(a, confidence)}),
    ]
    if a.moments.residual_second_moment is not None:
        checks.append(CheckPower("residual_whiteness", whiteness_power(a, confidence)))
    checks.append(CheckPower("nis", {None: nis_power(a, confidence)}))
    return checks


def power_rows(a: CovarianceAnalysis, n: int, confidence: float = 0.99) -> list[dict]:
    """``power``: per check a row for the whole check (``part`` None) and, for a check of two parts, one per
    part: ``power_low``, ``power_high`` at N = ``n``, ``detectable`` and ``detection_n``."""
    rows = []
    for check in check_families(a, confidence):
        at_n = {part: family.bracket(n) for part, family in check.parts.items()}  # each family once at n
        found = {part: detection_n(lambda k, f=family: f.bracket(k)[0]) for part, family in check.parts.items()}
        reached = [k for k in found.values() if k is not None]
        rows.append(power_row(check.name, None, CheckPower.combine(at_n.values()), min(reached) if reached else None))
        rows.extend(power_row(check.name, part, at_n[part], found[part]) for part in check.parts if part is not None)
    return rows


def problem_power(problem, n: int, confidence: float, analysis=None) -> tuple[list[dict] | None, str | None]:
    """``summary.json``'s ``power`` for a verification problem, and why it is None where it is.

    A fixed-gain problem gets :func:`power_rows` of its exact analysis (its budget left out; ``analysis``
    where the caller already has it, with the pairs); any other (scale-bias: gains that depend on the
    data) gets None and the reason."""
    from kalcal.analysis.fixed_gain import analyze_problem
    from kalcal.montecarlo.problem import FixedGainProblem

    if not isinstance(problem, FixedGainProblem):
        return None, "no exact analysis: the filter's gains depend on the data"
    if analysis is None:
        analysis = analyze_problem(problem, budget=False)
    return power_rows(analysis, n, confidence), None
