"""The fitted filter's NIS tail against chi-square(p): a check of the innovations' shape that the fit cannot force.

The fit's noise settings scale every S_k, and at the maximum of log L the mean NIS is p whatever the
innovations' distribution (with the four default stds free, d log L / d log sigma = 0 gives it exactly):
the mean-NIS half of the diagnostics then passes by construction. Its shape is not fitted: for a filter
whose innovations are Gaussian the NIS of each fix is chi-square(p), and the count of fixes above its
``1 - TAIL`` quantile is Binomial(K, TAIL) (the fixes' normalized innovations are independent). A log
with heavy-tailed errors (gross GNSS errors, a fault the model lacks) has at the same mean NIS more
fixes far out in the tail. The check is two-sided, at ``alpha`` (binomial quantiles alpha / 2 each way);
its lower side acts only where the lower quantile is at least 1 (above about 7,600 fixes at the
defaults: :func:`lower_side_fixes`).

On a gated fit the check does not apply (:func:`not_applicable`): the gate removes every fix whose NIS
exceeds its chi2.ppf(CONFIDENCE, p), which at ``--gate 0.999`` is this tail's threshold itself and at
any lower confidence lies below it, so the tail's count is 0 whatever the innovations, and the lower
side would fail every long enough gated log. The gate's own rule (more rejections than its share
allows) judges the gross outliers instead.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from kalcal.core.steps import nis as normalized_square
from kalcal.stats.distributions import binom_isf, binom_ppf, binom_test, chi2_isf, chi2_ppf

#: the tail whose share is tested: above the chi-square(p) 99.9% quantile
TAIL = 0.001
#: the check's false-alarm rate for Gaussian innovations (added to the diagnostics' 1%)
ALPHA = 0.001


@dataclass(frozen=True)
class NisTail:
    """The count of fixes with NIS above chi2.ppf(1 - tail, p), with its binomial bounds.

    ``lower``/``upper`` are the Binomial(fixes, tail) quantiles at alpha / 2 and 1 - alpha / 2; ``passed``
    when ``lower <= count <= upper``; ``pvalue`` the two-sided exact binomial test's.
    """

    fixes: int
    threshold: float  #: chi2.ppf(1 - tail, p)
    tail: float
    count: int
    expected: float
    lower: int
    upper: int
    alpha: float
    pvalue: float
    passed: bool

    def as_dict(self) -> dict:
        """``diagnostics.nis_tail``: the fields, with ``applies`` true."""
        return {"applies": True, **asdict(self)}

    def sentence(self) -> str:
        """The failure in words ("" when passed)."""
        if self.passed:
            return ""
        side = "heavier" if self.count > self.upper else "lighter"
        bound = self.upper if self.count > self.upper else self.lower
        return (
            f"{self.count} of {self.fixes} fixes have NIS above the chi-square {quantile(self.tail)} quantile "
            f"({self.threshold:.3g}); "
            f"a Gaussian filter has {self.expected:.3g}, {'at most' if side == 'heavier' else 'at least'} {bound} at "
            f"{1 - self.alpha:.1%}: the innovations are {side}-tailed than Gaussian"
            + (" (gross GNSS errors: try --gate)" if side == "heavier" else "")
        )


def quantile(tail: float) -> str:
    """The ``1 - tail`` quantile's name: ``"99.9%"`` for 0.001."""
    return f"{100.0 * (1.0 - tail):.10g}%"


def lower_side_fixes(tail: float = TAIL, alpha: float = ALPHA) -> int:
    """The fewest fixes at which the check's lower bound is 1 or more (7,601 at the defaults): below them
    only the upper side can fail."""
    fixes = int(np.ceil(-np.log(alpha / 2) / tail))  # (1 - tail)^K < alpha / 2 from about K = -log(alpha / 2) / tail
    while binom_ppf(alpha / 2, fixes - 1, tail) >= 1:
        fixes -= 1
    while binom_ppf(alpha / 2, fixes, tail) < 1:
        fixes += 1
    return fixes


def not_applicable(gate: float, p: int = 2) -> dict:
    """``diagnostics.nis_tail`` of a gated fit, where the check does not apply: ``applies`` false and the reason."""
    cut, threshold = float(chi2_ppf(gate, p)), float(chi2_isf(TAIL, p))
    removed = (
        f"at or below the chi-square {quantile(TAIL)} quantile ({threshold:.3g}) the check counts, so the count would be 0 "
        "whatever the innovations"
        if cut <= threshold * (1 + 1e-9)
        else f"so the fixes it counts (NIS above {threshold:.3g}) are cut off at the gate and their binomial bounds do not hold"
    )
    return {
        "applies": False,
        "passed": None,
        "gate_threshold": cut,
        "threshold": threshold,
        "reason": (
            f"not applied with --gate {gate:g}: the gate rejects every fix with NIS above {cut:.3g}, {removed}; the "
            "gate's own excess rule (more rejections than its share allows) judges gross outliers instead"
        ),
    }


def nis_tail(normalized: np.ndarray, *, tail: float = TAIL, alpha: float = ALPHA) -> NisTail:
    """Test the share of NIS above the chi-square(p) ``1 - tail`` quantile against Binomial(K, tail).

    Parameters
    ----------
    normalized : ndarray, shape (K, p)
        The fixes' normalized innovations L_k^{-1} r_k (dimensionless).
    """
    fixes, p = normalized.shape
    nis = normalized_square(normalized)
    threshold = float(chi2_isf(tail, p))
    count = int(np.count_nonzero(nis > threshold))
    lower = int(binom_ppf(alpha / 2, fixes, tail))
    upper = int(binom_isf(alpha / 2, fixes, tail))
    pvalue = binom_test(count, fixes, tail)
    return NisTail(fixes, threshold, tail, count, fixes * tail, lower, upper, alpha, pvalue, lower <= count <= upper)
