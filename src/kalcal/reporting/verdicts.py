"""The page's sections on the checks: what failed (cause, shortfall, measurement) and the verdicts table."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from kalcal.reporting.markup import esc, table
from kalcal.reporting.text import confidence_statement, levels_text, measured_text, shortfall
from kalcal.stats.text import (
    CHECK_PVALUE_FIELD,
    check_bounds_text,
    direction_text,
    explained_by_text,
    fmt,
    pvalue_text,
    written_nan,
)

__all__ = ["failures_section", "verdicts_section"]


def _cause(test: Mapping[str, Any]) -> Mapping[str, Any]:
    return test.get("cause") or {}


def failures_section(summary: Mapping[str, Any]) -> str:
    """What failed, each failed check led by its likely cause; a short all-passed note when none did."""
    failed = [t for t in summary["tests"] if not t["passed"]]
    if not failed:
        return (
            '<section class="allpass" id="failures"><strong>Every check passed</strong>: '
            f"{esc(confidence_statement(summary))}.</section>"
        )
    items = []
    for test in failed:
        cause = _cause(test)
        reason = cause.get("reason")
        if cause.get("explained_by") == "false_alarm":  # the truth equals the filter: no cause to name
            lead = f'<p class="cause">{esc(reason.rstrip("."))}.</p>'
        elif reason:
            lead = f'<p class="cause">Likely cause: {esc(reason.rstrip("."))}.</p>'
        else:
            lead = '<p class="cause">Likely cause: not identified by the check; see the figures below.</p>'
        explained, direction = explained_by_text(cause), direction_text(cause)
        if explained:
            lead += f"<p><strong>Accounted for by:</strong> {esc(explained)}.</p>"
        if direction:
            lead += f"<p><strong>Direction:</strong> {esc(direction)}.</p>"
        pvalue = pvalue_text(test.get("pvalue"), written_nan(summary, CHECK_PVALUE_FIELD))
        items.append(
            f'<h3 id="fail-{esc(test["name"])}">{esc(test["name"])}</h3>{lead}'
            f"<p><strong>By how much:</strong> {esc(shortfall(test))} ({esc(pvalue)} "
            f"against {esc(fmt(1 - test['confidence'], 3))}).</p>"
            f"<p><strong>Measured:</strong> {esc(measured_text(test))}.</p>"
        )
    names = ", ".join(t["name"] for t in failed)
    return (
        '<section class="failures" id="failures"><h2>What failed</h2>'
        f"<p>{len(failed)} of {len(summary['tests'])} checks failed ({esc(names)}).</p>{''.join(items)}</section>"
    )


def verdicts_section(summary: Mapping[str, Any]) -> str:
    """One row per check: statistic, bounds, verdict, detail and levels."""
    rows = []
    for test in summary["tests"]:
        state = "pass" if test["passed"] else "fail"
        rows.append(
            f'<tr class="{state}" id="check-{esc(test["name"])}"><td><code>{esc(test["name"])}</code></td>'
            f'<td class="num">{esc(fmt(test["statistic"]))}</td>'
            f'<td class="num">{esc(check_bounds_text(test))}</td>'
            f'<td class="{state}">{"passed" if test["passed"] else "FAILED"}</td>'
            f"<td>{esc(test['detail'])}<br><small>{esc(levels_text(test, summary))}</small></td></tr>"
        )
    return (
        '<h2 id="verdicts">Verdicts</h2>'
        + table(("check", "statistic", "bounds", "passed", "detail"), rows)
    )
