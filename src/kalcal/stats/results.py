"""The result objects of the statistical checks, the family-wise p-values they carry, and how a check builds one.

A check holds a family of m comparisons to a false-alarm rate alpha = 1 - confidence. Its p-value is
family-wise adjusted (Bonferroni), so that ``passed == (pvalue >= alpha)`` holds exactly:

* a family of m two-sided normal comparisons with largest |z|: ``min(1, m * 2 * (1 - Phi(|z|)))``;
* a family of m two-sided chi-square comparisons: ``min(1, m * min_k 2 * min(F(x_k), 1 - F(x_k)))``;
* a check made of several parts (e.g. the covariance check: element-wise family and centered NEES), each
  held to an equal share alpha / n_parts: ``min(1, n_parts * min(part p-values))``.

Each of these passes exactly when every comparison lies inside its Bonferroni bound, so a correct filter
fails a check with probability at most alpha (the bounds are exact quantiles; for the normal families
up to the normal approximation of the ensemble means and covariances).

Building a result, the steps every check shares: its z-statistics (:func:`standardized`, zero standard
errors included) and the largest of them (:func:`max_abs`), their words (:func:`sd_text`,
:func:`where_text`, :func:`zero_se_text`), the cause of a failure (:func:`failed_cause`,
:func:`centered_cause`) and the result itself (:func:`check_result`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from kalcal.stats.distributions import chi2_cdf, chi2_sf, normal_sf

if TYPE_CHECKING:  # only for the annotations: the result objects load without the Monte Carlo
    from kalcal.montecarlo.problem import ProblemInfo

#: what a failure is accounted for by (each value of ``Cause.explained_by``), in words
EXPLAINED_BY_TEXT = {
    "model_error": "the mean error the filter's model predicts against the truth (the deterministic model error)",
    "mean_error": "the nonzero mean error (centered on the ensemble means this check passes; see mean_error)",
    "false_alarm": "a false alarm: the truth equals the filter, and a correct filter fails a check at its stated rate",
    "approximation": ("the filter's approximation: the truth is the filter's own model, so neither a model error nor "
                      "the noise settings account for it, only how the filter approximates the nonlinear model"),
}
#: which way a filter's covariance is wrong (each value of ``Cause.direction``), in words
DIRECTION_TEXT = {
    "overconfident": "overconfident: the actual spread is larger than the filter's P (noise settings too small)",
    "underconfident": "underconfident: the actual spread is smaller than the filter's P (noise settings too large)",
}
EXPLAINED_BY = tuple(EXPLAINED_BY_TEXT)
DIRECTIONS = tuple(DIRECTION_TEXT)


@dataclass(frozen=True)
class Cause:
    """Why a check failed, as data.

    Attributes
    ----------
    explained_by : {"model_error", "mean_error", "false_alarm"} or None
        ``"model_error"``: the mean error the filter's model predicts against the truth (the filter run on
        the truth's mean trajectory) accounts for the failure; ``"mean_error"``: the failure of a raw-moment
        check goes away once centered on the ensemble means (see the ``mean_error`` check);
        ``"false_alarm"``: the truth equals the filter, so the failure is one of the false alarms a correct
        filter gives at the check's stated rate (:func:`as_false_alarm`), with no direction; None: not
        accounted for (or the check passed).
    direction : {"overconfident", "underconfident"} or None
        ``"overconfident"``: the actual spread is larger than the filter's covariance says (noise
        settings too small); ``"underconfident"``: smaller. None where the check says nothing about it.
    reason : str or None
        The same diagnosis in one sentence (the end of the check's ``detail``); None when there is none.
    """

    explained_by: str | None = None
    direction: str | None = None
    reason: str | None = None

    def __post_init__(self):
        if self.explained_by not in (None, *EXPLAINED_BY):
            raise ValueError(f"explained_by: expected one of {EXPLAINED_BY} or None, got {self.explained_by!r}")
        if self.direction not in (None, *DIRECTIONS):
            raise ValueError(f"direction: expected one of {DIRECTIONS} or None, got {self.direction!r}")


NO_CAUSE = Cause()


def with_reason(measured: str, cause: Cause) -> str:
    """A check's ``detail``: the measured text, then the cause's reason as its last sentence."""
    return f"{measured}. {cause.reason}" if cause.reason else measured


def _check_invariant(kind: str, name: str, pvalue: float, alpha: float, passed: bool) -> None:
    if not 0.0 < alpha < 1.0:
        raise ValueError(f"{kind} {name!r}: the false-alarm rate must lie in (0, 1), got {alpha!r}")
    if bool(passed) != bool(pvalue >= alpha):
        raise ValueError(f"{kind} {name!r}: passed={passed} disagrees with pvalue {pvalue!r} at alpha {alpha!r}")


@dataclass(frozen=True)
class CheckPart:
    """One test of a check made of several, at its share of the check's alpha.

    Attributes
    ----------
    name : str
        ``"elements"`` or ``"centered_nees"`` (covariance), ``"nis"`` or ``"ljung_box"`` (calibrate).
    statistic : float
        The comparison that decides the part (largest |z|, or the value with the smallest p-value).
    pvalue : float
        Family-wise over the part's comparisons; ``passed == (pvalue >= alpha)`` (``alpha``, not
        ``1 - confidence``, which may differ from it in the last bit).
    lower, upper : float or None
        The bounds every comparison of the part was held against (None for a one-sided part).
    confidence : float
        The part's own level, 1 - alpha.
    alpha : float
        The part's share of the check's false-alarm rate.
    comparisons : int
        Comparisons in the part's Bonferroni family.
    passed : bool
    """

    name: str
    statistic: float
    pvalue: float
    lower: float | None
    upper: float | None
    confidence: float
    alpha: float
    comparisons: int
    passed: bool

    def __post_init__(self):
        _check_invariant("part", self.name, self.pvalue, self.alpha, self.passed)

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class CheckResult:
    """One check: its statistic, family-wise p-value, every bound it was held against, and the verdict.

    Attributes
    ----------
    name : str
    statistic : float
        The headline statistic: for a check of one family its deciding comparison; for a check of
        several parts, the first part's (every part's own is in ``parts``).
    pvalue : float
        Family-wise adjusted p-value; ``passed == (pvalue >= 1 - confidence)``.
    lower, upper : float or None
        The headline statistic's bounds (None for a one-sided check); for a check of several parts, the
        first part's (at its share of alpha).
    confidence : float
        The check's level: a correct filter fails it with probability at most 1 - confidence.
    comparisons : int
        Comparisons the check's verdict rests on (over all its parts).
    passed : bool
    detail : str
        What was measured, where, and (on failure) why, in words: ``measured``, then the cause's
        ``reason`` as its last sentence (:func:`with_reason`).
    cause : Cause
        The diagnosis as data (all None when the check passed).
    parts : tuple of CheckPart
        The tests of a check made of several (empty for a check of one family).
    measured : str or None
        What was measured and where, without the reason (the report shows the two apart, so that nothing
        parses ``detail``). None is taken as ``detail`` when the cause has no reason; with a reason it
        must be given.
    """

    name: str
    statistic: float
    pvalue: float
    lower: float | None
    upper: float | None
    confidence: float
    comparisons: int
    passed: bool
    detail: str
    cause: Cause = NO_CAUSE
    parts: tuple[CheckPart, ...] = field(default_factory=tuple)
    measured: str | None = None
    #: the effect sizes beside the exact verdict, with their intervals and tolerance verdicts
    #: (:mod:`kalcal.stats.effects`); empty where the run kept none
    effect_sizes: tuple = field(default_factory=tuple)
    #: every effect's interval inside its band; None where there are none
    within_tolerance: bool | None = None
    #: the tolerance verdict of those effects: ``pass``, ``fail`` (one outside its band) or ``undecided``
    #: (:func:`kalcal.stats.effects.overall_outcome`); None where there are none
    tolerance_outcome: str | None = None

    def __post_init__(self):
        _check_invariant("check", self.name, self.pvalue, 1.0 - self.confidence, self.passed)
        if self.measured is None:
            if self.cause.reason:
                raise ValueError(f"check {self.name!r}: a cause with a reason needs the measured text apart")
            object.__setattr__(self, "measured", self.detail)
        if self.detail != with_reason(self.measured, self.cause):
            raise ValueError(
                f"check {self.name!r}: detail {self.detail!r} is not the measured text {self.measured!r} and the reason"
            )

    def as_dict(self) -> dict:
        """The entry of ``summary.json``'s ``tests`` list (``parts`` as a list of dicts)."""
        document = asdict(self)
        document["parts"] = [part.as_dict() for part in self.parts]
        document["effect_sizes"] = [effect.as_dict() for effect in self.effect_sizes]
        return document


def false_alarm_cause(confidence: float) -> Cause:
    """The cause of a failed check where the truth equals the filter: a false alarm at the stated rate."""
    return Cause(
        explained_by="false_alarm",
        reason=(
            f"False alarm: the truth equals the filter, so nothing is wrong with it; a correct filter fails this check "
            f"with probability at most {1.0 - confidence:.3g} (its stated rate), and this run is one of those: rerun "
            "with another seed (--seed)"
        ),
    )


def as_false_alarm(check: CheckResult) -> CheckResult:
    """A failed check of a run whose truth equals its filter, named a false alarm instead of given a cause.

    Where the truth equals the filter (in everything the checks see) a failure cannot have a cause: the
    check failed at its stated rate, and a direction or a model error would be a diagnosis of nothing.
    A passed check is returned as it is.
    """
    if check.passed:
        return check
    cause = false_alarm_cause(check.confidence)
    return replace(check, cause=cause, detail=with_reason(check.measured, cause))


def as_approximation(check: CheckResult, approximation: str) -> CheckResult:
    """A failed check of a run whose truth is the filter's own nonlinear model, its cause named as the
    filter's ``approximation`` (a phrase: "the EKF's linearization of h about its estimate").

    The checks' own causes assume a linear filter whose failure can only come from its model or its noise
    settings ("noise settings too small", "heavy-tailed noise", "its model or prior mean differs"); where
    the truth is the filter's model, those are false. The direction the check found stays in the words (the
    P too small or too large is a fact of the run), not in ``direction``, whose words name the noise
    settings. A passed check is returned as it is."""
    if check.passed:
        return check
    found = {"overconfident": "; the filter's P is smaller than the actual spread (overconfident)",
             "underconfident": "; the filter's P is larger than the actual spread (underconfident)"}.get(check.cause.direction, "")
    cause = Cause(explained_by="approximation", reason=(
        f"The truth is the filter's own model, so neither its model nor its noise settings are wrong: the failure is "
        f"{approximation}{found}"))
    return replace(check, cause=cause, detail=with_reason(check.measured, cause))


def normal_family_pvalue(worst: float, comparisons: int) -> float:
    """Bonferroni p-value of a family of ``comparisons`` two-sided normal tests with largest |z| ``worst``.

    min(1, m * 2 * (1 - Phi(|z|))); 0 for an infinite |z| (a nonzero value with zero standard error),
    NaN for a NaN statistic.
    """
    if math.isnan(worst):
        return math.nan
    return float(min(1.0, comparisons * 2.0 * normal_sf(abs(worst))))


def chi2_two_sided_pvalues(values: np.ndarray, dof: float, count: float) -> np.ndarray:
    """Two-sided p-values of means of ``count`` terms whose sum is chi-square with ``dof`` degrees of freedom.

    p_k = min(1, 2 * min(F(count * x_k), 1 - F(count * x_k))), F the chi-square(dof) distribution.
    """
    total = np.asarray(values, dtype=float) * count
    return np.minimum(1.0, 2.0 * np.minimum(chi2_cdf(total, dof), chi2_sf(total, dof)))


def family_pvalue(pvalues: np.ndarray | Sequence[float], comparisons: int | None = None) -> float:
    """Bonferroni: min(1, m * min(p)) over m comparisons (default: as many as p-values); NaN if any is NaN."""
    pvalues = np.asarray(pvalues, dtype=float).ravel()
    if pvalues.size == 0:
        return 1.0
    if np.isnan(pvalues).any():
        return math.nan
    m = pvalues.size if comparisons is None else comparisons
    return float(min(1.0, m * float(pvalues.min())))


def combined_pvalue(parts: Sequence[CheckPart]) -> float:
    """A check of n parts, each at alpha / n: min(1, n * min(part p-values))."""
    return family_pvalue([part.pvalue for part in parts])

def where_text(info: ProblemInfo, k: int, *names: str) -> str:
    """``names`` at update ``k``'s time, for a detail: ``"v/p at t = 1.2 s"``."""
    return f"{'/'.join(names)} at t = {info.update_times[k]:g} s"


def max_abs(z: np.ndarray) -> tuple[float, tuple[int, ...]]:
    """The largest |z| and its index."""
    index = np.unravel_index(int(np.argmax(np.abs(z))), z.shape)
    return float(np.abs(z[index])), tuple(int(i) for i in index)


def safe_ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    """num / den, 0 where den is not positive: for display only, never for a test."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)


def standardized(num: np.ndarray, se: np.ndarray, mask: np.ndarray | None = None) -> tuple[np.ndarray, int, int]:
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


def zero_se_text(passing: int, failing: int, what: str) -> str:
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


def sd_text(value: float) -> str:
    """A number of standard deviations for a detail, two decimals (``inf`` as such)."""
    return "inf" if np.isinf(value) else f"{value:.2f}"


def failed_cause(reason: str, explained_by: str | None = None, direction: str | None = None) -> Cause:
    """The cause of a failed check: its ``reason``, and what explains it or its direction where known."""
    return Cause(explained_by=explained_by, direction=direction, reason=reason)


def centered_cause(rest_z: np.ndarray, m: int, alpha: float, on: str, explained: str, otherwise: str) -> Cause:
    """The cause of a failed raw-moment check, from its z-statistics ``rest_z`` recentred on ``on``: the
    mean error when the recentred family of ``m`` comparisons passes at ``alpha``, else ``otherwise``."""
    rest, _ = max_abs(rest_z)
    lead = f"Centered on {on} the largest is {sd_text(rest)}: "
    if normal_family_pvalue(rest, m) >= alpha:
        return failed_cause(lead + explained, explained_by="mean_error")
    return failed_cause(lead + otherwise)


def check_result(
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
