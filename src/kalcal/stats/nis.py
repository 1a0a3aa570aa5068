"""The NIS check (each update's mean NIS within its chi-square(N p) / N bounds), its power, and the innovation gate's excess rule.

The NIS of one innovation is :func:`kalcal.core.steps.nis`; a correct filter's is chi-square(p), so the
mean of N independent realizations' is chi-square(N p) / N at each update, two-sided, and the K updates
are held to alpha by Bonferroni (:func:`check_nis`). :func:`nis_power` is the check's power under a
truth from the exact analysis. An innovation gate rejects a fix whose NIS exceeds a chi-square(p)
quantile: :func:`gate_excess` says when it rejected far more than its share.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from kalcal.core.steps import nis
from kalcal.linalg import whitener
from kalcal.stats.bounds import chi2_mean_bounds
from kalcal.stats.distributions import binom_isf
from kalcal.stats.power import ChiSquareFamily
from kalcal.stats.results import Cause, CheckResult, chi2_two_sided_pvalues, check_result, failed_cause, family_pvalue

if TYPE_CHECKING:  # annotations only: the gate's rule serves calibrate and fit, which load no Monte Carlo
    from kalcal.analysis.fixed_gain import CovarianceAnalysis
    from kalcal.montecarlo.accumulators import EnsembleStatistics
    from kalcal.montecarlo.problem import ProblemInfo

__all__ = ["GATE_EXCESS_ALPHA", "check_nis", "gate_excess", "nis_power"]

#: a gate's rejections are "far more than its share" above Binomial(fixes, 1 - gate)'s upper quantile at this
#: probability: the chance that settings which describe the fixes are told otherwise
GATE_EXCESS_ALPHA = 1e-4


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
            centered = s.mean_nis - nis(s.mean_normalized_residual)
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


def nis_power(a: CovarianceAnalysis, confidence: float) -> ChiSquareFamily:
    """The check's family under the truth: N times each update's mean NIS, a weighted noncentral chi-square
    in the filter's whitened innovations (A = S^-1/2 C S^-T/2, mean S^-1/2 E[r]), against its bounds."""
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
        nis(mu),  # |mu|^2, the NIS of the mean innovation
        np.einsum("ka,kab,kb->k", mu, ratio, mu),
        0,
        bounds,
    )


def gate_excess(rejected: int, gated: int, gate: float) -> str:
    """A sentence when an innovation gate rejected far more of ``gated`` fixes than its (1 - gate) share; "" otherwise.

    Under settings that describe the fixes each fix's NIS is chi-square(p) given the fixes before it, so
    the gate rejects each with probability 1 - gate, independently: the count is Binomial(gated, 1 - gate).
    "Far more" is above that binomial's upper ``GATE_EXCESS_ALPHA`` quantile
    (:func:`kalcal.stats.distributions.binom_isf`), so the sentence comes for such settings with
    probability at most ``GATE_EXCESS_ALPHA`` (1e-4), at any number of fixes. (Near the rule of mean + 3
    binomial standard deviations + 3 fixes it replaces: 6 of 1,000 fixes at a 0.999 gate against 7, 1,119 of
    100,000 at 0.99 against 1,097; that rule's false alarm ranged from 1e-5 to 1e-3 with the count.)

    Parameters
    ----------
    rejected, gated : int
        The fixes rejected, and the fixes the gate judged (rejected ones included).
    gate : float
        The gate's confidence, in (0, 1).
    """
    share = 1.0 - gate
    limit = float(binom_isf(GATE_EXCESS_ALPHA, gated, share))
    if rejected <= limit:
        return ""
    return (
        f"the gate rejected {rejected} of {gated} fixes, far more than its {share:.3g} share (more than {limit:.0f} "
        f"comes with probability below {GATE_EXCESS_ALPHA:g} for settings that describe the fixes)"
    )
