"""The page's view of the exact analysis: the filter/exact/ensemble sigma figure's words, the self-check and the power."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from kalcal.stats.power import power_line
from kalcal.reporting.markup import esc, table
from kalcal.stats.text import fmt

__all__ = ["SIGMA_EXACT", "SIGMA_EXACT_CAPTION", "SIGMA_EXACT_TITLE", "power_section", "self_check_section", "sigma_exact_spec"]

#: the figure's file stem
SIGMA_EXACT = "sigma_exact"
SIGMA_EXACT_TITLE = "Error σ per state: the filter's √P, the exact √P_true and the ensemble"
SIGMA_EXACT_CAPTION = (
    "The exact σ (covariance analysis of the same filter against the same truth, no sampling) is what the "
    "filter's error really has: where the dashed filter σ lies apart from it the filter is mistuned, seen "
    "without sampling noise. The ensemble σ should stay inside the shaded self-check band around the exact "
    "curve: that is the bench agreeing with theory, whatever the filter's verdict."
)


def sigma_exact_spec(dataset, exact_cov) -> tuple:
    """(key, group, title, caption, draw) of the figure, ``draw(path)`` plotting ``stats.nc`` against P_true (K, d, d)."""
    from kalcal.plots.ensemble import plot_sigma_exact  # matplotlib: where the figures are drawn, not the page

    return SIGMA_EXACT, "ensemble", SIGMA_EXACT_TITLE, SIGMA_EXACT_CAPTION, lambda path: plot_sigma_exact(dataset, exact_cov, path)


def self_check_section(summary: Mapping[str, Any]) -> str:
    """The self-check of the bench (summary.json's ``self_check``): its sentence and its parts; empty for a
    summary from before it."""
    check = summary.get("self_check")
    if not check:
        return ""
    head = '<h2 id="self-check">Self-check of the bench</h2>'
    note = (
        "<p class='sub'>The Monte Carlo ensemble against the exact analysis of the same filter and truth. "
        "It checks the engine and its sums, not the filter, and does not enter the verdict.</p>"
    )
    if check.get("agrees") is None:
        return head + note + f"<p>{esc(check.get('detail') or check.get('reason'))}</p>"
    rows = [
        f"<tr><td>{esc(part['name'])}</td><td class='num'>{esc(fmt(part['statistic']))}</td>"
        f"<td class='num'>±{esc(fmt(part['upper']))}</td><td class='num'>{esc(fmt(part['comparisons']))}</td>"
        f"<td class='num'>{esc(fmt(part['pvalue']))}</td><td>{'agrees' if part['passed'] else 'DISAGREES'}</td></tr>"
        for part in check["parts"]
    ]
    return (
        head
        + note
        + f"<p>{esc(check['detail'])}</p>"
        + table(("part", "largest z", "bound", "comparisons", "p-value", "result"), rows)
    )


def _bracket(row: Mapping[str, Any]) -> str:
    low, high = f"{row['power_low']:.2f}", f"{row['power_high']:.2f}"
    return low if low == high else f"{low}–{high}"


def power_section(summary: Mapping[str, Any]) -> str:
    """The checks' power at the run's N (summary.json's ``power``): verify's power line and, per check and
    part, the bracket [power_low, power_high] and ``detection_n`` (folded); the reason where there is none; empty for
    a summary from before it."""
    if "power" not in summary:
        return ""
    head = '<h2 id="power">Power of the checks</h2>'
    note = (
        "<p class='sub'>The probability that each check fails at this N under the truth, from the exact "
        "analysis of the same filter and truth (Bonferroni's bracket [max, sum] over its comparisons), and the "
        "smallest N at which its conservative end reaches 0.99 (docs/analysis.md).</p>"
    )
    n = summary["realizations"]
    line = power_line(summary["power"], n, summary.get("power_reason"), bool(summary.get("power_truth_equals_filter")))
    if summary["power"] is None:
        return head + note + f"<p>{esc(line)}</p>"
    rows = [
        f"<tr><td>{esc(row['name'])}</td><td>{esc(row['part'] or '(whole check)')}</td>"
        f"<td class='num'>{esc(_bracket(row))}</td>"
        f"<td class='num'>{esc(fmt(row['detection_n']) if row['detectable'] else 'not detected')}</td></tr>"
        for row in summary["power"]
    ]
    return (
        head
        + note
        + f"<p>{esc(line)}</p>"
        + "<details><summary>Power of each check and part</summary>"
        + table(("check", "part", f"power at N = {n:,}", "detected from N"), rows)
        + "</details>"
    )
