"""The steps the checks share: z-statistics (zero standard errors included), their text, causes and results."""

from __future__ import annotations

import numpy as np

from kalcal.montecarlo.problem import ProblemInfo
from kalcal.stats.results import Cause, CheckResult, normal_family_pvalue, with_reason

__all__ = [
    "centered_cause",
    "check_result",
    "failed_cause",
    "max_abs",
    "safe_ratio",
    "sd_text",
    "standardized",
    "where_text",
    "zero_se_text",
]


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
