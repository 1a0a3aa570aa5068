"""Whether to trust a calibration: the filter's innovations over the log against their theory.

For a consistent filter the normalized innovations nu_k = L_k^{-1} r_k (S_k = L_k L_k^T) are white
N(0, I). Two tests, each at half of alpha = 1 - confidence, so that a consistent filter is called
inconsistent with probability at most alpha (up to the simulated null's scatter, below):

* ``nis`` (size): K * mean NIS is chi-square with K p degrees of freedom, two-sided at alpha / 2;
* ``ljung_box`` (whiteness): the Ljung-Box statistic of each of the p components of nu over ``lags``
  lags, at alpha / (2 p) each (Bonferroni over the components), against its null distribution for iid
  normal series of the log's length simulated with a fixed seed (``kalcal.calibration.ljung_box``).

The p-values are family-wise: the Ljung-Box part's is min(1, p * min over components), the whole's
min(1, 2 * min(part p-values)), and ``consistent == (pvalue >= 1 - confidence)``.

The NIS test is exact. The Ljung-Box part's usual chi-square(lags) reference is asymptotic, and short logs
do not reach it: with 20 lags white innovations exceed its bound 1.5 times as often as stated at a 2.5%
tail and 2.8 times at 0.25% for K = 200 fixes (1.1 and 1.3 times for K = 1000; 10^5 white sequences).
So each component's p-value is the Monte Carlo one, (1 + #{simulated >= Q}) / (1 + B), over B simulated
white series of min(K, 500) fixes with (B + 1) alpha / (2 p) >= 20: valid (never below the exact tail
probability, on average over the draws) at every K, and, for K > 500, taken from the shorter series'
heavier-tailed null, whose realized rate falls with K. It costs about 0.15 s of CPU at confidence 0.99 whatever the
log's length (cached per length, lags and B). Chosen over fewer lags for short logs (still asymptotic, with
no size guarantee) and over a statistic of exact finite-sample law (the autocorrelations' exact law needs
K x K eigenproblems): the statistic, its lags and its power stay those of the Ljung-Box test. With the
draws fixed, each log length has its own realized rate, which scatters about the nominal by about
1 / sqrt(20), 22%, relative (measured at 0.25%: 0.73 to 1.28 times for K = 100 to 500), so the bound
holds on average over the draw, not at every length (about 1.1% instead of 1% at K = 250).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from kalcal.calibration.ljung_box import (
    draws_for,
    largest_passing,
    ljung_box_statistics,
    monte_carlo_pvalues,
    simulated_null,
)
from kalcal.core.steps import nis as normalized_square
from kalcal.stats.bounds import chi2_bounds_at
from kalcal.stats.distributions import chi2_isf  # scipy.stats's values, without its import
from kalcal.stats.results import Cause, CheckPart, chi2_two_sided_pvalues, combined_pvalue, family_pvalue

CONSISTENT = "noise settings consistent with the data"
#: the tests, each held to an equal share of alpha
PARTS = ("nis", "ljung_box")
#: the confidence of a calibration's diagnostics
CONFIDENCE = 0.99


def _lags(n_fixes: int) -> int:
    """The Ljung-Box lags of a log of n_fixes fixes: 20, fewer below 100 fixes."""
    return int(max(1, min(20, n_fixes // 5)))


def whiteness_null(n_fixes: int, p: int, confidence: float = CONFIDENCE) -> np.ndarray | None:
    """The sorted simulated Ljung-Box null, (B,), that :func:`innovation_diagnostics` holds n_fixes fixes of
    p components to at ``confidence``; None where the series is too short for a statistic. Cached: it
    depends on min(n_fixes, 500) and the lags (20 from 100 fixes on), the same for every log of 500 fixes
    or more."""
    lags = _lags(n_fixes)
    if lags >= n_fixes:
        return None
    return simulated_null(n_fixes, lags, draws_for((1.0 - confidence) / len(PARTS) / p))


@dataclass(frozen=True)
class InnovationDiagnostics:
    """The innovation tests of one calibration and a plain-language verdict.

    ``nis_lower``/``nis_upper`` bound the mean NIS and ``ljung_box_upper`` each component's Ljung-Box
    statistic, at the parts' share of alpha (``parts`` holds each test's statistic, bounds, level and
    p-value). ``pvalue`` is family-wise, with ``consistent == (pvalue >= 1 - confidence)``; ``cause``
    gives the direction of a size failure (too large innovations: ``"overconfident"``).
    """

    fixes: int
    confidence: float
    mean_nis: float
    nis_lower: float
    nis_upper: float
    nis_fraction_above_95: float  #: share of fixes whose NIS exceeds its 95% quantile (about 0.05 expected)
    ljung_box_lags: int
    ljung_box_statistic: list[float]  #: per component
    ljung_box_pvalue: list[float]  #: per component, Monte Carlo, not adjusted for the p components
    ljung_box_upper: float  #: bound on each component's statistic (from the simulated null)
    pvalue: float
    consistent: bool
    verdict: str
    cause: Cause
    parts: tuple[CheckPart, ...]

    def __post_init__(self):
        if self.consistent != bool(self.pvalue >= 1.0 - self.confidence):
            raise ValueError(
                f"consistent={self.consistent} disagrees with pvalue {self.pvalue!r} at confidence {self.confidence!r}"
            )

    def to_dict(self) -> dict:
        """``summary.json``'s ``diagnostics``: the fields, ``parts`` as a list of documents."""
        document = asdict(self)
        document["parts"] = [part.as_dict() for part in self.parts]
        return document

    as_dict = to_dict


def monte_carlo_pvalue_text(pvalue: float, draws: int) -> str:
    """A Monte Carlo p-value (1 + #{simulated >= Q}) / (1 + B) in words: ``p = 0.0031``, or at its floor
    1 / (1 + B), where no simulated value reached the statistic, ``p < 0.00013`` (the tail probability is
    below the resolution of B draws, not equal to it)."""
    floor = 1.0 / (1.0 + draws)
    if pvalue <= floor * (1.0 + 1e-9):
        shown = float(f"{floor:.2g}")
        if shown < floor:  # rounded down: the next value of two digits up, so the printed bound holds
            shown = float(f"{floor * (1 + 0.05):.2g}")
        return f"p ≤ {shown:.2g}" if shown == floor else f"p < {shown:.2g}"
    return f"p = {pvalue:.2g}"


def _nan_max(values: list[float]) -> float:
    """The largest value that is a number (NaN when none is), whatever their order."""
    finite = [v for v in values if not np.isnan(v)]
    return max(finite) if finite else float("nan")


def innovation_diagnostics(
    normalized: np.ndarray, names: tuple[str, ...] = ("position", "velocity"), confidence: float = CONFIDENCE
) -> InnovationDiagnostics:
    """Test normalized innovations (K, p) for size and whiteness, each at half of 1 - confidence.

    Parameters
    ----------
    normalized : ndarray, shape (K, p)
        L_k^{-1} r_k for each fix (dimensionless).
    names : tuple of str
        The components, for the verdict.
    confidence : float
        In (0, 1): a consistent filter is called inconsistent with probability at most 1 - confidence,
        up to the scatter of the whiteness part's simulated null (see the module's docstring).
    """
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence!r}")
    n_fixes, p = normalized.shape
    alpha = 1.0 - confidence
    share = alpha / len(PARTS)
    nis = normalized_square(normalized)  # each fix's NIS, the squared norm of its normalized innovation
    mean_nis = float(nis.mean())
    lower, upper = chi2_bounds_at(share, 1, n_fixes * p, n_fixes)  # two-sided, at the NIS part's share
    nis_p = float(chi2_two_sided_pvalues(np.array([mean_nis]), n_fixes * p, n_fixes)[0])
    size = CheckPart("nis", mean_nis, nis_p, lower, upper, 1.0 - share, share, 1, nis_p >= share)
    above = float(np.mean(nis > chi2_isf(0.05, p)))
    lags, null = _lags(n_fixes), whiteness_null(n_fixes, p, confidence)
    # A degenerate series (constant, or too short for the lags) has no statistic: its NaN p-value then
    # fails the whiteness part (untestable is not white).
    if null is not None:
        values = ljung_box_statistics(normalized.T, lags)
        pvalues = [float(v) for v in monte_carlo_pvalues(null, values)]
        lb_upper = largest_passing(null, p, share)
    else:
        values, pvalues, lb_upper = np.full(p, np.nan), [float("nan")] * p, float("nan")
    statistics = [float(v) for v in values]
    lb_p = family_pvalue(pvalues)
    whiteness = CheckPart("ljung_box", _nan_max(statistics), lb_p, None, lb_upper, 1.0 - share, share, p, lb_p >= share)
    parts = (size, whiteness)
    pvalue = combined_pvalue(parts)
    problems, direction = [], None
    if not size.passed and mean_nis > p:
        direction = "overconfident"
        problems.append(
            f"innovations too large (mean NIS {mean_nis:.3g} above {upper:.3g}): the noise settings are too "
            "small, or the log holds an error the model lacks"
        )
    elif not size.passed:
        direction = "underconfident"
        problems.append(f"innovations too small (mean NIS {mean_nis:.3g} below {lower:.3g}): the noise settings are too large")
    correlated = [names[c] for c in range(p) if p * pvalues[c] < share]
    untestable = [names[c] for c in range(p) if np.isnan(pvalues[c])]
    if untestable:
        problems.append(
            f"{' and '.join(untestable)} innovations not testable for whiteness (constant, or too short for "
            f"{lags} lags)"
        )
    if correlated:
        problems.append(
            f"{' and '.join(correlated)} innovations correlated in time (Ljung-Box over {lags} lags, "
            f"{monte_carlo_pvalue_text(float(np.nanmin(pvalues)), null.size)} against {share / p:.2g}): the model misses a dynamic (a drifting bias, a scale "
            "factor) or the fixes are correlated"
        )
    verdict = CONSISTENT if not problems else "; ".join(problems)
    return InnovationDiagnostics(
        fixes=n_fixes,
        confidence=confidence,
        mean_nis=mean_nis,
        nis_lower=lower,
        nis_upper=upper,
        nis_fraction_above_95=above,
        ljung_box_lags=lags,
        ljung_box_statistic=statistics,
        ljung_box_pvalue=pvalues,
        ljung_box_upper=lb_upper,
        pvalue=pvalue,
        consistent=pvalue >= alpha,
        verdict=verdict,
        cause=Cause(direction=direction, reason=None if not problems else verdict),
        parts=parts,
    )
