"""The covariance check: the ensemble covariance of the whitened error against the identity, and the cause of a failure.

**Whitening.** For a correct filter the error of each realization at update k is e_k ~ N(0, P_k) given
everything the filter saw, P_k the filter's own covariance, so eps_k = L_k^-1 e_k (P_k = L_k L_k^T, lower
Cholesky factor) is N(0, I) and, over the N independent realizations, iid. Where P_k is the same in
every realization (fixed gains) the whitened moments follow from the raw ones (L^-1 C L^-T); where P_k
depends on the data (scale-bias) each realization is whitened by its own P_k in the Monte Carlo sums
(:mod:`kalcal.montecarlo.accumulators`): the mean P is then no valid reference (by Jensen's inequality a
whitening by it is not N(0, I), and the bound would be anticonservative).

With W_k the centered ensemble covariance of eps_k (divisor N - 1), every comparison has an exact law at
every N (no normal approximation; the earlier element-wise sd (P_il^2 + P_ii P_ll) / N, a normal
approximation, had a far tail several times too light where a Bonferroni family reaches, so a correct
filter failed about 1.4% of the time at N = 100 and confidence 0.99):

* each whitened variance: (N - 1) W_k,ii ~ chi-square(N - 1), two-sided;
* each whitened correlation r = W_k,il / sqrt(W_k,ii W_k,ll), i < l: r sqrt(N - 2) / sqrt(1 - r^2) ~
  t(N - 2), two-sided (the sample correlation of two independent normal samples);
* the centered NEES tr(W_k): (N - 1) tr(W_k) ~ chi-square(d (N - 1)), two-sided.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from kalcal.analysis.fixed_gain import CovarianceAnalysis
from kalcal.linalg import whitener
from kalcal.montecarlo.accumulators import EnsembleStatistics
from kalcal.montecarlo.problem import ProblemInfo
from kalcal.stats.bounds import COVARIANCE_PARTS, centered_nees_bounds, covariance_element_bound
from kalcal.stats.distributions import chi2_cdf, chi2_sf, normal_isf, t_sf
from kalcal.stats.power import ChiSquareFamily, NormalFamily
from kalcal.stats.results import (
    Cause,
    CheckPart,
    CheckResult,
    check_result,
    chi2_two_sided_pvalues,
    combined_pvalue,
    failed_cause,
    family_pvalue,
    max_abs,
    safe_ratio,
    sd_text,
    standardized,
)

__all__ = [
    "Whitened",
    "centered_nees",
    "check_covariance",
    "correlation_pvalues",
    "correlation_z",
    "covariance_power",
    "element_pvalues",
    "element_z",
    "t_equivalent_z",
    "chi2_equivalent_z",
    "whitened_moments",
]


class Whitened(NamedTuple):
    """The moments of the whitened errors eps_k = L_k^-1 e_k, K updates, d states."""

    mean: np.ndarray  #: E[eps_k], (K, d)
    cov: np.ndarray  #: centered ensemble covariance of eps_k, divisor N - 1, (K, d, d)
    second: np.ndarray  #: E[eps_k eps_k^T], (K, d, d)
    estimate: np.ndarray  #: E[eps_k xhat_k^T], (K, d, d)
    #: (K,) the updates whose shared P_k is not positive definite (no whitening: their moments are zero
    #: here, and the checks compare them by whether the raw moments vanish too)
    singular: np.ndarray


def _lower_solve(factor: np.ndarray, values: np.ndarray) -> np.ndarray:
    """L^-1 values for lower-triangular factors (K, d, d) and values (K, d, ...) (a solve, never an inverse)."""
    return np.linalg.solve(factor, values)


def whitened_moments(s: EnsembleStatistics) -> Whitened:
    """The whitened moments of ``s``: its own where each realization was whitened by its own P_k
    (``s.whitened_second_moment``), else the raw moments whitened by the shared P_k (``s.filter_cov``)."""
    n = s.count
    k, d = s.mean_error.shape
    if s.whitened_second_moment is not None:
        mean, second, estimate = s.mean_whitened_error, s.whitened_second_moment, s.whitened_estimate
        cov = (second - mean[:, :, None] * mean[:, None, :]) * (n / (n - 1))
        return Whitened(mean, cov, second, estimate, np.zeros(k, dtype=bool))
    p = s.filter_cov
    singular = np.zeros(k, dtype=bool)
    try:
        factor = np.linalg.cholesky(p)
    except np.linalg.LinAlgError:  # some P_k not positive definite: factor the others one by one
        factor = np.broadcast_to(np.eye(d), (k, d, d)).copy()
        for i in range(k):
            try:
                factor[i] = np.linalg.cholesky(p[i])
            except np.linalg.LinAlgError:
                singular[i] = True
    mean = _lower_solve(factor, s.mean_error[:, :, None])[:, :, 0]

    def both(m: np.ndarray) -> np.ndarray:  # L^-1 M L^-T
        return np.swapaxes(_lower_solve(factor, np.swapaxes(_lower_solve(factor, m), 1, 2)), 1, 2)

    cov, second = both(s.error_cov), both(s.error_second_moment)
    estimate = _lower_solve(factor, s.error_estimate)
    keep = ~singular
    zero = lambda a: np.where(keep.reshape((k,) + (1,) * (a.ndim - 1)), a, 0.0)  # noqa: E731
    return Whitened(zero(mean), zero(cov), zero(second), zero(estimate), singular)


def correlation_pvalues(r: np.ndarray, dof: float) -> np.ndarray:
    """Two-sided p-values of sample correlations r whose t = r sqrt(dof) / sqrt(1 - r^2) is t(dof).

    dof = N - 2 for the centered correlation of two independent normal samples of N, N - 1 for the
    uncentered one of a N(0, 1) sample with any sample independent of it (the orthogonality and
    whiteness checks). |r| = 1 gives 0; a NaN r (no spread) gives NaN.
    """
    r = np.asarray(r, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.abs(r) * np.sqrt(dof) / np.sqrt(np.maximum(1.0 - r * r, 0.0))
    return np.minimum(1.0, 2.0 * t_sf(t, dof))


#: tails below the smallest normal double are subnormal (few significant bits) or 0: the transforms take over
_SMALLEST = float(np.finfo(float).tiny)


def t_equivalent_z(t: np.ndarray, dof: float) -> np.ndarray:
    """The signed normal z with the same two-sided tail as each t(dof) value (inf stays inf, NaN NaN).

    Families of t comparisons are then held to their normal Bonferroni bounds exactly: 2 (1 - Phi(|z|))
    is the t's two-sided p-value. Where that tail is below the smallest normal double (|t| of about 38
    and more at large dof), Wallace's transform z = (8 dof + 1) / (8 dof + 3) sqrt(dof ln(1 + t^2 / dof)) stands
    in for it, so that a far-off value is shown as a finite number of sd: its p-value is 0 all the same."""
    t = np.asarray(t, dtype=float)
    tail = t_sf(np.abs(t), dof)
    exact = normal_isf(tail)
    with np.errstate(divide="ignore", invalid="ignore"):
        wallace = (8.0 * dof + 1.0) / (8.0 * dof + 3.0) * np.sqrt(dof * np.log1p(t * t / dof))
    far = (tail < _SMALLEST) & np.isfinite(t)
    return np.sign(t) * np.where(far, wallace, exact)


def chi2_equivalent_z(total: np.ndarray, dof: float) -> np.ndarray:
    """The normal |z| with the same two-sided tail as each chi-square(dof) value ``total``.

    Where that tail is below the smallest normal double, the signed root of the deviance,
    sqrt(x - dof - dof ln(x / dof)), stands in for it on either side of the mean (a finite number of sd
    for a far-off variance, within 0.5% of the exact side at the switch; its p-value is 0 all the same)."""
    total = np.asarray(total, dtype=float)
    tail = np.minimum(chi2_cdf(total, dof), chi2_sf(total, dof))
    exact = normal_isf(tail)
    with np.errstate(divide="ignore", invalid="ignore"):
        deviance = np.sqrt(np.maximum(total - dof - dof * np.log(total / dof), 0.0))
    return np.where((tail < _SMALLEST) & np.isfinite(total), deviance, exact)


def correlation_z(moment: np.ndarray, power: np.ndarray, dof: float) -> tuple[np.ndarray, int, int]:
    """Sample correlations r = moment / sqrt(power) as signed normal-equivalent z of their t(dof) law.

    ``power`` is the product of the two samples' mean squares (centered or not, as ``moment``). A zero
    ``power`` (no spread) gives z = 0 for an exactly zero moment and +-inf otherwise, counted as by
    :func:`~kalcal.stats.results.standardized` (its two counts are returned).
    """
    r, zero_pass, zero_fail = standardized(moment, np.sqrt(np.maximum(power, 0.0)))
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(np.isinf(r), r, r * np.sqrt(dof) / np.sqrt(np.maximum(1.0 - r * r, 0.0)))
    return t_equivalent_z(t, dof), zero_pass, zero_fail


def element_pvalues(cov: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Two-sided p-values of the whitened covariance's elements, and the sign of each deviation.

    Parameters
    ----------
    cov : ndarray, shape (..., d, d)
        Centered ensemble covariances (divisor N - 1) of N = ``count`` whitened errors (N(0, I) for a
        correct filter).
    count : int
        N.

    Returns
    -------
    pvalues, signs : ndarray, shape (..., d, d)
        The diagonal: (N - 1) W_ii against chi-square(N - 1), sign(W_ii - 1); off it: the correlation
        r_il against t(N - 2), sign(r_il) (symmetric).
    """
    var = np.diagonal(cov, axis1=-2, axis2=-1)
    total = (count - 1) * var
    diag_p = np.minimum(1.0, 2.0 * np.minimum(chi2_cdf(total, count - 1), chi2_sf(total, count - 1)))
    with np.errstate(divide="ignore", invalid="ignore"):
        r = cov / np.sqrt(var[..., :, None] * var[..., None, :])
    pvalues = correlation_pvalues(r, count - 2)
    signs = np.sign(r)
    eye = np.eye(cov.shape[-1], dtype=bool)
    pvalues = np.where(eye, diag_p[..., None, :] * eye, pvalues)
    signs = np.where(eye, np.sign(var - 1.0)[..., None, :] * eye, signs)
    return pvalues, signs


def element_z(cov: np.ndarray, count: int) -> np.ndarray:
    """Each whitened covariance element as the normal |z| of its own exact two-sided test, (..., d, d).

    The diagonal's by :func:`chi2_equivalent_z` ((N - 1) W_ii against chi-square(N - 1)), the
    correlations' by :func:`t_equivalent_z` (t(N - 2)): the |z| whose two-sided normal tail is the
    element's p-value of :func:`element_pvalues`, finite also where that tail underflows."""
    var = np.diagonal(cov, axis1=-2, axis2=-1)
    diag_z = chi2_equivalent_z((count - 1) * var, count - 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = cov / np.sqrt(var[..., :, None] * var[..., None, :])
        t = r * np.sqrt(count - 2) / np.sqrt(np.maximum(1.0 - r * r, 0.0))
    z = np.abs(t_equivalent_z(t, count - 2))
    return np.where(np.eye(cov.shape[-1], dtype=bool), diag_z[..., None, :], z)


def centered_nees(error_cov: np.ndarray, filter_cov: np.ndarray) -> np.ndarray:
    """Centered mean NEES tr(P_k^-1 C_k), (K,), from the ensemble covariance C of e (K, d, d) and P (K, d, d).

    The trace of the whitened covariance where every realization shares P_k; for a consistent filter
    (N - 1) times it is chi-square with d (N - 1) degrees of freedom (the mean error taken out, so a mean
    error does not lift it). Where P_k varies the check takes tr(W_k) of the per-realization whitening
    (:func:`whitened_moments`) instead."""
    return np.trace(np.linalg.solve(filter_cov, error_cov), axis1=1, axis2=2)


def _singular_text(passing: int, failing: int) -> str:
    texts = []
    if passing:
        texts.append(f"{passing} update(s) where P and the ensemble covariance are both exactly zero, counted as passed")
    if failing:
        texts.append(
            f"{failing} update(s) where P is not positive definite and the ensemble covariance differs from it, "
            "counted as failed"
        )
    return "".join(f"; {text}" for text in texts)


def check_covariance(s: EnsembleStatistics, info: ProblemInfo, confidence: float) -> CheckResult:
    """The whitened errors' ensemble covariance equals I, element by element and through the centered NEES.

    Two parts, each at half the check's alpha, so that the check's false-alarm rate is at most alpha, at
    every N (every comparison's law is exact; see the module docstring):

    * ``elements``: the K d (d + 1) / 2 whitened variances (chi-square) and correlations (t), each
      two-sided; Bonferroni. The statistic is the largest |z| of the elements' own tests
      (:func:`element_z`: the |z| of the smallest p-value, finite also where it underflows), against the
      normal quantile of the family (the same bound as before);
    * ``centered_nees``: tr(W_k), whose (N - 1) multiple is chi-square(d (N - 1)), two-sided for K
      comparisons.

    The raw deviations (C - P) / sd, sd^2 = (P_il^2 + P_ii P_ll) / N, are shown in the detail only.
    The direction of a failure is stated only where the data say it: the sign of the whitened variances
    outside their bound (W_ii > 1: overconfident; none if they disagree), else the side the centered
    NEES left its bounds on when that part failed; a failure of correlations alone has no direction
    (the correlations differ, the variances agree).
    """
    alpha = 1.0 - confidence
    share = alpha / len(COVARIANCE_PARTS)
    n_updates, d, _ = s.filter_cov.shape
    upper = np.triu_indices(d)
    m = n_updates * upper[0].size
    bound = covariance_element_bound(confidence, n_updates, d)
    white = whitened_moments(s)
    pvalues, signs = element_pvalues(white.cov, s.count)
    # a P_k that cannot whiten: its comparisons pass only where P_k and the ensemble covariance are both zero
    zero_pass = white.singular & np.all(s.error_cov == 0, axis=(1, 2)) & np.all(s.filter_cov == 0, axis=(1, 2))
    zero_fail = white.singular & ~zero_pass
    pvalues = np.where(zero_pass[:, None, None], 1.0, np.where(zero_fail[:, None, None], 0.0, pvalues))
    family = pvalues[:, upper[0], upper[1]]
    smallest = float(np.nanmin(family)) if not np.all(np.isnan(family)) else np.nan
    p_elements = family_pvalue(family)
    # the statistic: the largest |z| of the elements' own tests (finite where a p-value underflows)
    z = element_z(white.cov, s.count)
    z = np.where(zero_pass[:, None, None], 0.0, np.where(zero_fail[:, None, None], np.inf, z))[:, upper[0], upper[1]]
    worst = float(np.nanmax(z)) if not np.isnan(smallest) else np.nan
    k, e = np.unravel_index(int(np.nanargmax(z)), z.shape) if not np.isnan(smallest) else (0, 0)
    i, l = int(upper[0][e]), int(upper[1][e])
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
    nees_values = np.trace(white.cov, axis1=1, axis2=2)
    dof = d * (s.count - 1)
    low, high = centered_nees_bounds(confidence, n_updates, d, s.count)
    nees_p = chi2_two_sided_pvalues(nees_values, dof, s.count - 1)
    nees_p = np.where(zero_pass, 1.0, np.where(zero_fail, 0.0, nees_p))
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
    detail = (
        f"largest whitened deviation {sd_text(worst)} sd ({_element_text(white.cov, s.count, info, k, i, l)}, "
        f"p = {smallest:.3g} of {m} comparisons), bound {bound:.2f} (at alpha / 2 = {share:.3g}); "
        + _raw_text(s, info)
        + f"; centered mean NEES from {nees_values.min():.4f} to {nees_values.max():.4f}, bounds [{low:.4f}, "
        f"{high:.4f}] (at alpha / 2)"
        + _singular_text(int(zero_pass.sum()), int(zero_fail.sum()))
    )
    diagnosis = Cause()
    if not passed:
        failing = pvalues * m < share
        diagnosis = _covariance_cause(signs, failing, nees, info, (int(k), i, l))
    return check_result(
        "covariance", worst, pvalue, None, bound, confidence, m + n_updates, passed, detail, diagnosis, parts=parts
    )


def _element_text(cov: np.ndarray, count: int, info: ProblemInfo, k: int, i: int, l: int) -> str:
    """The whitened comparison that decides the elements part, in words."""
    names = info.state_names
    where = f"at t = {info.update_times[k]:g} s"
    if i == l:
        return f"whitened variance of {names[i]} {cov[k, i, i]:.4g}, expected 1, chi-square({count - 1}) / {count - 1}, {where}"
    with np.errstate(divide="ignore", invalid="ignore"):
        r = cov[k, i, l] / np.sqrt(cov[k, i, i] * cov[k, l, l])
    return f"whitened correlation of {names[i]} and {names[l]} {r:.4f}, expected 0, t({count - 2}), {where}"


def _raw_text(s: EnsembleStatistics, info: ProblemInfo) -> str:
    """The raw deviations of the ensemble covariance from the mean P, for the reader (no test rests on
    them: their normal approximation is too light in the far tail at small N)."""
    p = s.filter_cov
    diag = np.diagonal(p, axis1=1, axis2=2)
    sd = np.sqrt((p**2 + diag[:, :, None] * diag[:, None, :]) / s.count)
    upper = np.triu_indices(p.shape[1])
    z, _, _ = standardized((s.error_cov - p)[:, upper[0], upper[1]], sd[:, upper[0], upper[1]])
    raw, (k, e) = max_abs(z)
    i, l = int(upper[0][e]), int(upper[1][e])
    ratio = safe_ratio(np.diagonal(s.error_cov, axis1=1, axis2=2), diag)
    return (
        f"largest raw deviation |C - P| / sd {sd_text(raw)} in element ({info.state_names[i]}, {info.state_names[l]}) "
        f"at t = {info.update_times[k]:g} s (shown only); ensemble/filter variance ratio from {ratio.min():.3f} "
        f"to {ratio.max():.3f}"
    )


def _covariance_cause(
    signs: np.ndarray, failing: np.ndarray, nees: CheckPart, info: ProblemInfo, worst: tuple[int, int, int]
) -> Cause:
    """The direction of a failed covariance check, stated only where the data say it.

    ``signs`` (K, d, d) are the signs of the whitened deviations (W_ii - 1 on the diagonal, the
    correlation off it) and ``failing`` marks the comparisons outside the element-wise bound. A whitened
    variance outside the bound gives the direction by its sign (W_ii > 1: overconfident); failing
    variances of both signs give none. With no variance outside the bound, the centered NEES gives it
    when that part failed (above its bounds: overconfident); otherwise the failure is in a correlation
    alone (``worst`` = (k, i, l)): the correlation differs, the variances agree, and the direction is None.
    The whitened component i is state i less what states 0 ... i - 1 predict of it (Cholesky order).
    """
    sign_diag = np.diagonal(signs, axis1=1, axis2=2)
    out = np.diagonal(failing, axis1=1, axis2=2)
    if out.any():
        found = set(sign_diag[out].tolist())
        if len(found) > 1:
            over = sorted({info.state_names[i] for i in np.nonzero(out & (sign_diag > 0))[1]})
            under = sorted({info.state_names[i] for i in np.nonzero(out & (sign_diag < 0))[1]})
            return failed_cause(
                f"The whitened ensemble variance of {', '.join(over)} exceeds 1 and that of {', '.join(under)} falls "
                "short of it: no single direction (the noise settings are wrong in opposite ways)"
            )
        overconfident = found == {1.0}
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


def covariance_power(a: CovarianceAnalysis, confidence: float) -> dict[str, NormalFamily | ChiSquareFamily]:
    s, p = a.moments.error_cov, a.filter_cov
    n_updates, d, _ = p.shape
    i, l = np.triu_indices(d)
    # A = L^-1 S L^-T, L the lower Cholesky factor of P, as the check whitens: tr A = tr(P^-1 S),
    # tr A^2 = tr((P^-1 S)^2)
    w = whitener(p)
    ratio = w @ s @ np.swapaxes(w, 1, 2)
    # the elements part tests each whitened variance (chi-square, about N(A_ii, 2 A_ii^2 / N)) and each
    # whitened correlation rho = A_il / sqrt(A_ii A_ll) (t, about N(rho, (1 - rho^2)^2 / N)); under the
    # null A = I: variances 2 / N and 1 / N
    diag = np.diagonal(ratio, axis1=1, axis2=2)
    spread = np.sqrt(np.maximum(diag[:, :, None] * diag[:, None, :], 0.0))
    # a whitened state without spread under the truth: its correlations are undefined, taken as 0
    rho = np.divide(ratio, spread, out=np.zeros_like(ratio), where=spread > 0)
    on = (i == l)[None, :]
    elements = NormalFamily(
        np.where(on, diag[:, i] - 1.0, rho[:, i, l]).ravel(),
        np.where(on, 2.0 * diag[:, i] ** 2, (1.0 - rho[:, i, l] ** 2) ** 2).ravel(),
        np.broadcast_to(np.where(on, 2.0, 1.0), (n_updates, i.size)).ravel(),
        covariance_element_bound(confidence, n_updates, d),
    )
    zero = np.zeros(n_updates)

    def bounds(n: int) -> tuple[float, float]:
        low, high = centered_nees_bounds(confidence, n_updates, d, n)
        return low * (n - 1), high * (n - 1)

    nees = ChiSquareFamily(
        np.trace(ratio, axis1=1, axis2=2), np.einsum("kij,kji->k", ratio, ratio), zero, zero, -1, bounds
    )
    return dict(zip(COVARIANCE_PARTS, (elements, nees)))
