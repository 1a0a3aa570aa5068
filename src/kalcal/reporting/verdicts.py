"""The report page's sections on the checks: the answer, what failed, and the verdicts table.

The answer (the verdict's sentence and a row per check) leads the page; what failed (cause, shortfall,
measurement) is folded under each short cause, and the verdicts table in full is folded below.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from kalcal.reporting.answer import Answer
from kalcal.reporting.markup import esc, table
from kalcal.reporting.text import levels_text, measured_text, shortfall
from kalcal.stats.text import (
    CHECK_PVALUE_FIELD,
    check_bounds_text,
    direction_text,
    explained_by_text,
    fmt,
    pvalue_text,
    written_nan,
)

__all__ = ["answer_section", "checks_table", "failures_section", "verdicts_section"]


def _cause(test: Mapping[str, Any]) -> Mapping[str, Any]:
    return test.get("cause") or {}


def answer_section(answer: Answer, scope: str) -> str:
    """The verdict in one sentence with its cause, and what a verdict is about (``scope``)."""
    return (
        f'<section class="answer {esc(answer.verdict)}" id="answer"><p class="verdict">{esc(answer.sentence)}</p>'
        f"<p class='scope'>{esc(scope)}.</p></section>"
    )


def checks_table(answer: Answer) -> str:
    """One row per check: its name, verdict, p-value and short cause; a failed check's name links to its
    block under What failed."""
    rows = []
    for line in answer.checks:
        state = "pass" if line.passed else "fail"
        name = f"<code>{esc(line.name)}</code>"
        if not line.passed:
            name = f'<a href="#fail-{esc(line.name)}">{name}</a>'
        rows.append(
            f'<tr class="{state}"><td>{name}</td><td class="{state}">{"passed" if line.passed else "FAILED"}</td>'
            f'<td class="num">{esc(line.pvalue)}</td><td>{esc(line.cause)}</td></tr>'
        )
    return table(("check", "verdict", "p-value", "cause"), rows, css_class="checks", table_id="checks")


def left_out_note(summary: Mapping[str, Any]) -> str:
    """Below the checks: the updates no check covers and the checks left out, where the run says so
    (``summary.json``'s ``not_checked`` and ``checks_left_out``: a diffuse filter's diffuse period), and the
    run's ``notes`` (a model file's known inputs); "" else."""
    lines = []
    if summary.get("not_checked"):
        lines.append(f"<p>Not checked: {esc(summary['not_checked'])}.</p>")
    for name, why in (summary.get("checks_left_out") or {}).items():
        lines.append(f"<p><code>{esc(name)}</code> left out: {esc(why)}.</p>")
    for note in summary.get("notes") or ():
        lines.append(f"<p>Note: {esc(note)}.</p>")
    return "".join(lines)


def failures_section(summary: Mapping[str, Any], answer: Answer | None = None) -> str:
    """What failed: each failed check folded under its name and short cause (from ``answer``), and led by
    its likely cause when opened; nothing when every check passed (the answer says so)."""
    failed = [t for t in summary["tests"] if not t["passed"]]
    if not failed:
        return ""
    short = {line.name: line.cause for line in answer.checks} if answer is not None else {}
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
        summary_line = f"<code>{esc(test['name'])}</code>"
        if test["name"] in short:
            summary_line += f": {esc(short[test['name']])}"
        items.append(
            f'<details id="fail-{esc(test["name"])}"><summary>{summary_line}</summary>{lead}'
            f"<p><strong>By how much:</strong> {esc(shortfall(test))} ({esc(pvalue)} "
            f"against {esc(fmt(1 - test['confidence'], 3))}).</p>"
            f"<p><strong>Measured:</strong> {esc(measured_text(test))}.</p></details>"
        )
    names = ", ".join(t["name"] for t in failed)
    return (
        '<section class="failures" id="failures"><h2>What failed</h2>'
        f"<p>{len(failed)} of {len(summary['tests'])} checks failed ({esc(names)}); open each for its likely "
        f"cause, by how much and what was measured.</p>{''.join(items)}</section>"
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
        '<h2 id="verdicts">Verdicts</h2><details><summary>Statistic, bounds, levels and detail of each check'
        "</summary>" + table(("check", "statistic", "bounds", "passed", "detail"), rows) + "</details>"
    )


def effects_section(summary: Mapping[str, Any]) -> str:
    """The effect sizes beside the exact verdicts, with their intervals and tolerance verdicts, and the
    Cramér–Rao bound per state (a lower bound); nothing for a run that kept none."""
    effects = summary.get("effect_sizes")
    if not effects:
        return ""
    rows = []
    shown = {"within": ("pass", "within"), "outside": ("fail", "OUTSIDE"), "undecided": ("undecided", "undecided")}
    for e in effects["overall"]:
        outcome = e.get("outcome", "within" if e["within_tolerance"] else "outside")
        state, text = shown[outcome]
        if outcome == "undecided":
            more = e.get("realizations_to_decide")
            text += f" (about {more:,} realizations would decide)" if more else " (the estimate lies on the edge)"
        name = e["name"] + (f" [{e['element']}]" if e["element"] else "")
        rows.append(
            f'<tr class="{state}"><td><code>{esc(name)}</code></td><td class="num">{esc(fmt(e["value"]))}</td>'
            f'<td class="num">[{esc(fmt(e["lower"]))}, {esc(fmt(e["upper"]))}]</td><td class="num">{esc(fmt(e["null"]))}</td>'
            f'<td class="num">[{esc(fmt(e["tolerance_lower"]))}, {esc(fmt(e["tolerance_upper"]))}]</td>'
            f'<td class="{state}">{esc(text)}</td></tr>'
        )
    conf = effects["overall"][0]["confidence"] if effects["overall"] else summary.get("confidence")
    html = (
        '<h2 id="effects">Effect sizes</h2>'
        f"<p>How far the filter departs from its model, beside the exact verdicts: each interval at confidence "
        f"{esc(fmt(conf))}; the tolerance verdict ({esc(effects['verdict'])}) passes when every interval lies in its band "
        f"(tolerance {esc(fmt(effects['tolerance']))}: P within that fraction of the mean squared error), fails when "
        "one lies wholly outside, and is undecided when one straddles an edge: the run is then too short to say, "
        "and the realizations that would decide are those at which the interval (its half-width falling as "
        "1/sqrt(N)) clears the nearest edge if the estimate stays where it is.</p>"
        + table(("effect", "value", "interval", "null", "tolerance band", "tolerance outcome"), rows)
    )
    crb = summary.get("cramer_rao")
    if crb:
        if crb["available"]:
            rows = [
                f'<tr><td>{esc(r["state"])}</td><td class="num">{esc(fmt(r["lower_bound"]))}'
                + ("" if r.get("lower_bound_se") is None else f' &plusmn; {esc(fmt(r["lower_bound_se"]))}')
                + '</td>'
                f'<td class="num">{esc(fmt(r["mse"]))} &plusmn; {esc(fmt(r["mse_se"]))}</td>'
                f'<td class="num">{esc(fmt(r["efficiency"]))}</td><td>{esc(r["unit"])}</td></tr>'
                for r in crb["final"]
            ]
            html += (
                f"<p>Posterior Cramér–Rao bound at the last update ({esc(crb['method'])}): a lower bound on the "
                "mean squared error of any estimator, biased or not (the posterior bound assumes no unbiasedness), "
                "against the ensemble's MSE; each with its Monte Carlo standard error (the bound's by the "
                "delete-one-group jackknife over the run's independent blocks, where it kept at least two).</p>"
                + table(("state", "lower bound", "MSE", "bound / MSE", "unit"), rows)
            )
        else:
            html += f"<p>No Cramér–Rao bound: {esc(crb['method'])}.</p>"
    return html + simulated_power_section(summary)


def _rate(count, rate, lower, upper) -> str:
    return "" if count is None else f"{count} ({fmt(rate)}; [{fmt(lower)}, {fmt(upper)}])"


def simulated_power_section(summary: Mapping[str, Any]) -> str:
    """Each check's rejection rate under each named alternative, by simulation, with its binomial interval
    (:mod:`kalcal.scenarios.nonlinear.power`); nothing where the run asked for none."""
    power = summary.get("power_by_simulation")
    if not power:
        return ""
    rows = [
        f'<tr><td>{esc(r["alternative"])}</td><td><code>{esc(r["check"])}</code></td>'
        f'<td class="num">{esc(_rate(r["exact_rejections"], r["exact_rate"], r["exact_lower"], r["exact_upper"]))}</td>'
        f'<td class="num">{esc(_rate(r["tolerance_rejections"], r["tolerance_rate"], r["tolerance_lower"], r["tolerance_upper"]))}</td>'
        f'<td class="num">{esc("" if r["tolerance_undecided"] is None else str(r["tolerance_undecided"]))}</td></tr>'
        for r in power["rows"]
    ]
    named = "; ".join(f"{name}: {text}" for name, text in power["alternatives"].items())
    return (
        '<h3 id="simulated-power">Power by simulation</h3>'
        f"<p>Rejections of each check over {power['runs']} repeated runs of {power['realizations']:,} realizations "
        f"per alternative, by simulation (not an exact power), with the rate and its Clopper–Pearson interval at "
        f"{esc(fmt(power['confidence']))}. {esc(named)}.</p>"
        + table(("alternative", "check", "exact rejections", "tolerance rejections (outside)", "tolerance undecided"), rows)
    )
