"""The suite of statistical checks of a filter against its Monte Carlo ensemble: run in order, the verdict, their power.

One module per check holds the check, its bounds and its power side by side: :mod:`kalcal.stats.mean_error`,
:mod:`kalcal.stats.covariance`, :mod:`kalcal.stats.orthogonality`, :mod:`kalcal.stats.whiteness`,
:mod:`kalcal.stats.nis`, :mod:`kalcal.stats.shape`.

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
shape                Kolmogorov-Smirnov distance of u = F_chi2(NEES) from   at alpha / 2 each: 2 P(D+ >= D),
                     U(0, 1), and of F_chi2(NIS), at 2047 grid points       Smirnov's law, m = K per part
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

The verdict is over the six checks: a correct filter passes every one with probability at least
1 - 6 alpha (Bonferroni over the checks; :func:`verdict_false_alarm_bound`). The shape check needs the
sums' NEES and NIS histograms (every run of the engine keeps them); its power is by simulation
(:func:`kalcal.stats.shape.shape_power`), not in :func:`power_rows`, whose families come from the exact
analysis of second moments.
"""

from __future__ import annotations

import numpy as np

from kalcal.analysis.fixed_gain import CovarianceAnalysis
from kalcal.montecarlo.accumulators import EnsembleStatistics
from kalcal.montecarlo.problem import ProblemInfo
from kalcal.stats.covariance import check_covariance, covariance_power
from kalcal.stats.mean_error import check_mean_error, mean_error_power
from kalcal.stats.nis import check_nis, nis_power
from kalcal.stats.orthogonality import check_orthogonality, orthogonality_power
from kalcal.stats.power import CheckPower, detection_n, power_row
from kalcal.stats.results import CheckResult
from kalcal.stats.shape import check_shape
from kalcal.stats.whiteness import check_residual_whiteness, whiteness_power

__all__ = [
    "DEFAULT_CONFIDENCE",
    "check_families",
    "power_rows",
    "problem_power",
    "run_checks",
    "verdict",
]

DEFAULT_CONFIDENCE = 0.99


def run_checks(
    s: EnsembleStatistics,
    info: ProblemInfo,
    confidence: float = DEFAULT_CONFIDENCE,
    expected_mean_error: np.ndarray | None = None,
    model_error_cause: str = "",
) -> list[CheckResult]:
    """Every check, in a fixed order: the shape check last, where the sums keep the NEES and NIS
    histograms (every run of the engine does; statistics built by hand from moments alone have none)."""
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence!r}")
    if info.capabilities is not None and info.capabilities.batch:
        return final_time_checks(s, info, confidence, expected_mean_error, model_error_cause)
    checks = [
        check_mean_error(s, info, confidence, expected_mean_error, model_error_cause),
        check_covariance(s, info, confidence),
        *(() if info.no_orthogonality else (check_orthogonality(s, info, confidence),)),  # left out: a diffuse filter's
        check_residual_whiteness(s, info, confidence),
        check_nis(s, info, confidence),
    ]
    if s.nees_histogram is not None and s.nis_histogram is not None:
        checks.append(check_shape(s, info, confidence))
    return checks


def final_time_checks(
    s: EnsembleStatistics,
    info: ProblemInfo,
    confidence: float = DEFAULT_CONFIDENCE,
    expected_mean_error: np.ndarray | None = None,
    model_error_cause: str = "",
) -> list[CheckResult]:
    """The checks of a batch estimator (``Capabilities.batch``: one final estimate per realization): the
    mean error, covariance, NIS and shape at the final update alone. There is no sequence of innovations to
    be white, and the earlier updates are not estimates the estimator gives, so residual_whiteness is left
    out and the families have m for K = 1. Orthogonality is left out too: E[e xhat^T] = 0 holds for a
    posterior mean (the error is orthogonal to every function of the data), and a batch estimator is a
    maximum likelihood that ignores the prior, whose error correlates with its estimate wherever the prior is
    as tight as the fit, while its intervals (mean error, covariance, NIS) are honest.

    The shape check takes its degrees of freedom from the statistics' shapes: the NEES against
    chi-square(d), d the checked states (``mean_error``'s), and the NIS against chi-square(q), q the
    estimator's own residual components (``mean_residual``'s: a fit's residual in the left null space of
    its Jacobian, whitened, has q = measurements - parameters components, each N(0, 1) to first order),
    as the NIS check holds its mean to q. Left out where the sums keep no histograms (statistics built by
    hand from moments alone), as in :func:`run_checks`."""
    import dataclasses

    last = slice(-1, None)

    def final(value):
        return value[last] if isinstance(value, np.ndarray) and value.ndim >= 1 and value.shape[0] == s.mean_error.shape[0] else value

    one = dataclasses.replace(
        s, **{f.name: final(getattr(s, f.name)) for f in dataclasses.fields(s) if f.name not in ("count", "residual_second_moment")},
        residual_second_moment=None,
    )
    info_one = dataclasses.replace(info, update_times=np.asarray(info.update_times)[last])
    expected = None if expected_mean_error is None else np.asarray(expected_mean_error)[last]
    checks = [
        check_mean_error(one, info_one, confidence, expected, model_error_cause),
        check_covariance(one, info_one, confidence),
        check_nis(one, info_one, confidence),
    ]
    if one.nees_histogram is not None and one.nis_histogram is not None:
        checks.append(check_shape(one, info_one, confidence))
    return checks


def verdict(checks: list[CheckResult]) -> str:
    """``"pass"`` when every check passed, else ``"fail"``."""
    return "pass" if all(c.passed for c in checks) else "fail"


def check_families(a: CovarianceAnalysis, confidence: float = 0.99) -> list[CheckPower]:
    """The five checks' families, in :func:`run_checks`' order (the
    whiteness check only where the analysis has the pair moments E[r_k r_j^T])."""
    checks = [
        CheckPower("mean_error", {None: mean_error_power(a, confidence)}),
        CheckPower("covariance", covariance_power(a, confidence)),
    ]
    if not a.info.no_orthogonality:  # a diffuse filter's estimate is not a posterior mean: the check is left out
        checks.append(CheckPower("orthogonality", {None: orthogonality_power(a, confidence)}))
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
    from kalcal.montecarlo.problem import capabilities_of

    caps = capabilities_of(problem)
    if not caps.exact_analysis:
        return None, f"no exact analysis: {caps.no_exact_analysis()}"
    if analysis is None:
        analysis = analyze_problem(problem, budget=False)
    return power_rows(analysis, n, confidence), None
