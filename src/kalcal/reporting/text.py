"""What the page says about the checks, in plain words: levels, shortfalls and the verdict's meaning."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from kalcal.stats.bounds import verdict_false_alarm_bound
from kalcal.stats.text import (
    CHECK_PVALUE_FIELD,
    PART_PVALUE_FIELD,
    bounds_text,
    fmt,
    part_label,
    pvalue_text,
    written_nan,
)

__all__ = ["confidence_statement", "levels_text", "measured_text", "scope_statement", "shortfall"]

#: what a verification is about, on the console and the page: a PASS is read as being about a log otherwise
SCOPE_STATEMENT = (
    "kalcal verify tests the filter against its own settings (the truth of [truth]) on synthetic motion simulated "
    "from them, not against any log: a PASS says nothing about whether the model fits a log; for that, see "
    "`kalcal fit`'s `adequate`"
)


def levels_text(test: Mapping[str, Any], summary: Mapping[str, Any] | None = None) -> str:
    """Confidence, comparisons and family-wise p-value of a check and of each of its parts.

    A ``null`` p-value reads ``p = NaN (not computable)`` where ``summary``'s ``nonfinite.fields``
    counts NaN p-values under its key, else ``p not recorded``."""
    summary = summary or {}
    text = (
        f"{fmt(100 * test['confidence'])}% confidence, {fmt(test['comparisons'])} comparisons, "
        f"{pvalue_text(test.get('pvalue'), written_nan(summary, CHECK_PVALUE_FIELD))}"
    )
    for part in test.get("parts") or []:
        text += (
            f"; {part_label(part)} at {fmt(100 * part['confidence'])}%, {fmt(part['comparisons'])} comparisons, "
            f"{pvalue_text(part.get('pvalue'), written_nan(summary, PART_PVALUE_FIELD))}"
        )
    return text


def measured_text(test: Mapping[str, Any]) -> str:
    """What was measured, without the reason (which the page shows on its own): the check's ``measured``
    field; the whole ``detail`` for a summary written before that field (the detail is never parsed)."""
    measured = test.get("measured")
    return (test["detail"] if measured is None else measured).rstrip(".")


def _one_shortfall(test: Mapping[str, Any]) -> str:
    statistic, upper, lower = test["statistic"], test["upper"], test.get("lower")
    if statistic is None:
        return "the statistic is not a finite number (see the detail)"
    if statistic > upper:
        text = f"{fmt(statistic)} against an upper bound of {fmt(upper)}: {fmt(statistic - upper, 3)} above it"
        if upper > 0:
            text += f" ({fmt(statistic / upper, 3)} times the bound)"
        return text
    if lower is not None and statistic < lower:
        return f"{fmt(statistic)} against a lower bound of {fmt(lower)}: {fmt(lower - statistic, 3)} below it"
    return f"{fmt(statistic)}, within {bounds_text(test)}"


def shortfall(test: Mapping[str, Any]) -> str:
    """How far a failed check's statistics lie from their bounds (each failed part's), in words."""
    parts = test.get("parts") or []
    if not parts:
        return _one_shortfall(test)
    failed = [part for part in parts if not part["passed"]]
    return "; ".join(f"{part_label(part)}: {_one_shortfall(part)}" for part in failed or parts)


def confidence_statement(summary: Mapping[str, Any]) -> str:
    """What the page's verdict means: each check's level and the verdict's family-wise false-alarm bound."""
    confidence, checks = summary["confidence"], len(summary["tests"])
    bound = verdict_false_alarm_bound(confidence, checks)
    return (
        f"each check at {fmt(100 * confidence)}% confidence (a correct filter fails it with probability at most "
        f"{fmt(100 * (1 - confidence))}%); a correct filter fails at least one of the {checks} checks with "
        f"probability at most {fmt(100 * bound)}% (Bonferroni)"
    )


def scope_statement(summary: Mapping[str, Any] | None = None) -> str:
    """What the run's verdict is about (the filter on synthetic motion, not a log), in one line."""
    return SCOPE_STATEMENT
