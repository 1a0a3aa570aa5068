"""Statistical checks of a filter against its Monte Carlo ensemble, each with computed bounds.

Every check tests one property the theory promises for a correct filter, over all update times (and all
elements) at once: the family of comparisons is held to the stated confidence by a Bonferroni
correction (alpha / m for m comparisons), so a correct filter fails a check with probability at most
1 - confidence. N realizations, K updates, d states, p measurements.

==================== ===================================================== =====================================
check                statistic                                             bound
==================== ===================================================== =====================================
mean_error           max |mean(e) / se|, se = sqrt(ensemble var / N)       normal quantile, m = K d
covariance           max |ensemble cov - P| / sd, sd^2 = (P_il^2 +          normal quantile, m = K d (d + 1) / 2;
                     P_ii P_ll) / N; and mean centered NEES                 chi-square(d (N - 1)) / (N - 1), m = K
orthogonality        max |mean(e x^T)| / sqrt(E[e^2] E[x^2] / N)            normal quantile, m = K d^2
residual_whiteness   max over j < k of |mean(r_k r_j^T)| /                  normal quantile, m = p^2 K (K - 1) / 2
                     sqrt(E[r_k^2] E[r_j^2] / N)
nis                  mean NIS at the update farthest from p                 chi-square(N p) / N, m = K
==================== ===================================================== =====================================

The covariance check compares the *centered* ensemble covariance, so that a mean error is reported once,
by ``mean_error``; orthogonality, whiteness and NIS use raw moments, as the source report does, and
when they fail their detail says whether the mean error accounts for it (the centered statistic passes).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy import stats as sps

from kalcal.montecarlo.accumulators import EnsembleStatistics
from kalcal.montecarlo.problem import ProblemInfo

DEFAULT_CONFIDENCE = 0.99
#: where the source report quotes E[r_k r_j^T]
REPORT_RESIDUAL_PAIR = (23.8, 5.8)


@dataclass(frozen=True)
class CheckResult:
    """One check: its statistic, the bounds it was held against, and the verdict."""

    name: str
    passed: bool
    statistic: float
    lower: float | None
    upper: float
    confidence: float
    comparisons: int
    detail: str

    def as_dict(self) -> dict:
        return asdict(self)


def normal_bound(confidence: float, comparisons: int) -> float:
    """Two-sided normal quantile for a family of ``comparisons`` at family-wise ``confidence``."""
    return float(sps.norm.isf((1.0 - confidence) / (2.0 * comparisons)))


def chi2_mean_bounds(confidence: float, comparisons: int, dof: float, count: float) -> tuple[float, float]:
    """Bounds on the mean of ``count`` terms whose sum is chi-square with ``dof`` degrees of freedom."""
    tail = (1.0 - confidence) / (2.0 * comparisons)
    return float(sps.chi2.ppf(tail, dof) / count), float(sps.chi2.isf(tail, dof) / count)


def _where(info: ProblemInfo, k: int, *names: str) -> str:
    return f"{'/'.join(names)} at t = {info.update_times[k]:g} s"


def _max_abs(z: np.ndarray) -> tuple[float, tuple[int, ...]]:
    index = np.unravel_index(int(np.argmax(np.abs(z))), z.shape)
    return float(np.abs(z[index])), tuple(int(i) for i in index)


def _safe_ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)


def check_mean_error(
    s: EnsembleStatistics,
    info: ProblemInfo,
    confidence: float,
    expected: np.ndarray | None = None,
    cause: str = "",
) -> CheckResult:
    """E[e_k] = 0 for every update and state."""
    n_updates, d = s.mean_error.shape
    m = n_updates * d
    bound = normal_bound(confidence, m)
    se = np.sqrt(np.diagonal(s.error_cov, axis1=1, axis2=2) / s.count)
    z = _safe_ratio(s.mean_error, se)
    worst, (k, i) = _max_abs(z)
    sigma = np.sqrt(np.diagonal(s.filter_cov, axis1=1, axis2=2))
    in_sigma = _safe_ratio(s.mean_error, sigma)
    big, (kb, ib) = _max_abs(in_sigma)
    detail = (
        f"largest |mean error| {worst:.2f} standard errors ({_where(info, k, info.state_names[i])}); "
        f"largest in filter sigma {big:.2f} sigma ({_where(info, kb, info.state_names[ib])})"
    )
    passed = worst <= bound
    if not passed and expected is not None:
        predicted, (kp, ip) = _max_abs(_safe_ratio(expected, sigma))
        rest, _ = _max_abs(_safe_ratio(s.mean_error - expected, se))
        if predicted > 0 and rest <= bound:
            detail += (
                f". Explained by the predicted systematic error: {cause or 'the truth departs from the filter model'} "
                f"predicts a mean error of up to {predicted:.2f} sigma ({_where(info, kp, info.state_names[ip])}); "
                f"after removing it the largest deviation is {rest:.2f} standard errors, within {bound:.2f}"
            )
        elif predicted > 0:
            detail += (
                f". The predicted systematic error ({cause or 'truth against filter model'}) reaches "
                f"{predicted:.2f} sigma but does not explain all of it ({rest:.2f} standard errors remain)"
            )
        else:
            detail += ". The filter model predicts no mean error: its model or prior mean differs from the truth"
    return CheckResult("mean_error", bool(passed), worst, None, bound, confidence, m, detail)


def centered_nees(error_cov: np.ndarray, filter_cov: np.ndarray) -> np.ndarray:
    """Centered mean NEES tr(P_k^-1 C_k), (K,), from the ensemble covariance C of e (K, d, d) and P (K, d, d).

    For a consistent filter (N - 1) times it is chi-square with d (N - 1) degrees of freedom (the mean
    error taken out, so a mean error does not lift it)."""
    return np.trace(np.linalg.solve(filter_cov, error_cov), axis1=1, axis2=2)


def centered_nees_bounds(confidence: float, n_updates: int, d: int, count: int) -> tuple[float, float]:
    """Bounds of :func:`centered_nees` for K = ``n_updates`` comparisons of N = ``count`` realizations."""
    return chi2_mean_bounds(confidence, n_updates, d * (count - 1), count - 1)


def check_covariance(s: EnsembleStatistics, info: ProblemInfo, confidence: float) -> CheckResult:
    """Ensemble covariance of e equals the filter's P, element by element and through the centered NEES."""
    n_updates, d, _ = s.filter_cov.shape
    upper = np.triu_indices(d)
    m = n_updates * upper[0].size
    bound = normal_bound(confidence, m)
    p = s.filter_cov
    diag = np.diagonal(p, axis1=1, axis2=2)
    sd = np.sqrt((p**2 + diag[:, :, None] * diag[:, None, :]) / s.count)
    z = _safe_ratio(s.error_cov - p, sd)[:, upper[0], upper[1]]
    worst, (k, e) = _max_abs(z)
    i, l = int(upper[0][e]), int(upper[1][e])
    centered = centered_nees(s.error_cov, p)
    low, high = centered_nees_bounds(confidence, n_updates, d, s.count)
    nees_ok = bool(np.all((centered >= low) & (centered <= high)))
    ratio = _safe_ratio(np.diagonal(s.error_cov, axis1=1, axis2=2), diag)
    rk, ri = np.unravel_index(int(np.argmax(np.abs(np.log(np.where(ratio > 0, ratio, 1.0))))), ratio.shape)
    detail = (
        f"largest deviation {worst:.2f} sd in element ({info.state_names[i]}, {info.state_names[l]}) at "
        f"t = {info.update_times[k]:g} s; ensemble/filter variance ratio from {ratio.min():.3f} to {ratio.max():.3f} "
        f"(extreme: {info.state_names[ri]} at t = {info.update_times[rk]:g} s); centered mean NEES from "
        f"{centered.min():.4f} to {centered.max():.4f}, bounds [{low:.4f}, {high:.4f}]"
    )
    passed = worst <= bound and nees_ok
    if not passed:
        if ratio[rk, ri] > 1:
            detail += ". The filter is overconfident: its P is smaller than the actual spread (noise settings too small)"
        else:
            detail += ". The filter is underconfident: its P is larger than the actual spread (noise settings too large)"
    return CheckResult("covariance", bool(passed), worst, None, bound, confidence, m, detail)


def check_orthogonality(s: EnsembleStatistics, info: ProblemInfo, confidence: float) -> CheckResult:
    """E[e_k xhat_k^T] = 0: the error is orthogonal to the estimate."""
    n_updates, d, _ = s.error_estimate.shape
    m = n_updates * d * d
    bound = normal_bound(confidence, m)
    e2 = np.diagonal(s.error_second_moment, axis1=1, axis2=2)
    x2 = np.diagonal(s.estimate_second_moment, axis1=1, axis2=2)
    z = _safe_ratio(s.error_estimate, np.sqrt(e2[:, :, None] * x2[:, None, :] / s.count))
    worst, (k, i, l) = _max_abs(z)
    detail = f"largest |E[e xhat^T]| {worst:.2f} standard errors (e_{info.state_names[i]} x xhat_{info.state_names[l]} at t = {info.update_times[k]:g} s)"
    passed = worst <= bound
    if not passed:
        centered = s.error_estimate - s.mean_error[:, :, None] * s.mean_estimate[:, None, :]
        var_e = np.diagonal(s.error_cov, axis1=1, axis2=2)
        var_x = x2 - s.mean_estimate**2
        rest, _ = _max_abs(_safe_ratio(centered, np.sqrt(var_e[:, :, None] * var_x[:, None, :] / s.count)))
        detail += (
            f". Centered on the means the largest is {rest:.2f}: "
            + ("the mean error accounts for it (see mean_error)" if rest <= bound else "error and estimate are correlated: the gains are not optimal for the truth")
        )
    return CheckResult("orthogonality", bool(passed), worst, None, bound, confidence, m, detail)


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
    moment = s.residual_second_moment  # (K, p, K, p)
    n_updates, p = moment.shape[:2]
    pairs = n_updates * (n_updates - 1) // 2
    m = max(1, p * p * pairs)
    bound = normal_bound(confidence, m)
    power = np.diagonal(moment.reshape(n_updates * p, n_updates * p)).reshape(n_updates, p)
    scale = np.sqrt(np.einsum("ka,jb->kajb", power, power) / s.count)
    z = _safe_ratio(moment, scale)
    lower = np.tril(np.ones((n_updates, n_updates), dtype=bool), -1)  # j < k
    masked = np.where(lower[:, None, :, None], z, 0.0)
    worst, (k, a, j, b) = _max_abs(masked)
    detail = (
        f"largest |E[r_k r_j^T]| {worst:.2f} standard errors ({info.measurement_names[a]} at t = {info.update_times[k]:g} s "
        f"with {info.measurement_names[b]} at t = {info.update_times[j]:g} s) over {pairs} pairs of updates"
    )
    passed = worst <= bound
    if not passed:
        mean = s.mean_residual
        centered = moment - np.einsum("ka,jb->kajb", mean, mean)
        var = power - mean**2
        cz = _safe_ratio(centered, np.sqrt(np.einsum("ka,jb->kajb", var, var) / s.count))
        rest, _ = _max_abs(np.where(lower[:, None, :, None], cz, 0.0))
        detail += (
            f". Centered on the residual means the largest is {rest:.2f}: "
            + ("nonzero mean residuals account for it (see mean_error)" if rest <= bound else "the innovations are correlated in time: the model's dynamics or noise are wrong")
        )
    return CheckResult("residual_whiteness", bool(passed), worst, None, bound, confidence, m, detail)


def check_nis(s: EnsembleStatistics, info: ProblemInfo, confidence: float) -> CheckResult:
    """Mean NIS at each update within its chi-square(N p) / N bounds."""
    n_updates, p = s.mean_residual.shape
    low, high = chi2_mean_bounds(confidence, n_updates, p * s.count, s.count)
    k = int(np.argmax(np.abs(s.mean_nis - p)))
    worst = float(s.mean_nis[k])
    passed = bool(np.all((s.mean_nis >= low) & (s.mean_nis <= high)))
    detail = (
        f"mean NIS from {s.mean_nis.min():.4f} to {s.mean_nis.max():.4f} (expected {p}); farthest at "
        f"t = {info.update_times[k]:g} s"
    )
    if not passed:
        if s.mean_normalized_residual is not None:
            # E|nu - E nu|^2 = E|nu|^2 - |E nu|^2 for the normalized innovations nu = L^{-1} r
            centered = s.mean_nis - np.sum(s.mean_normalized_residual**2, axis=1)
            if np.all((centered >= low) & (centered <= high)):
                detail += (
                    f". Centered on the mean innovations the mean NIS lies within the bounds "
                    f"({centered.min():.4f} to {centered.max():.4f}): the nonzero mean residuals account for it "
                    "(see mean_error)"
                )
                return CheckResult("nis", passed, worst, low, high, confidence, n_updates, detail)
        detail += (
            ". Innovations larger than the filter's S: the noise settings are too small"
            if worst > p
            else ". Innovations smaller than the filter's S: the noise settings are too large"
        )
    return CheckResult("nis", passed, worst, low, high, confidence, n_updates, detail)


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
