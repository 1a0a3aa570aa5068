"""``report.html``: one self-contained page with the run's verdicts, settings, figures and timing.

The page loads nothing from outside: figures are PNG data URIs, the style is inline, there is no script.
It holds no time stamp, so the same run directory always gives the same bytes. Every piece of text that
comes from the run (settings, check details, the command) is HTML-escaped.
"""

from __future__ import annotations

import base64
import html
import os
import struct
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from kalcal.filters.steady_state import SteadyStateView
from kalcal.report.figures import GROUPS, FigureEntry, SkippedFigure
from kalcal.verify.checks import verdict_false_alarm_bound
from kalcal.verify.text import (
    CHECK_PVALUE_FIELD,
    PART_LABELS,
    PART_PVALUE_FIELD,
    bounds_text,
    check_bounds_text,
    direction_text,
    explained_by_text,
    fmt,
    part_label,
    pvalue_text,
    written_nan,
)

__all__ = [
    "PART_LABELS",
    "bounds_text",
    "build_page",
    "check_bounds_text",
    "esc",
    "fmt",
    "levels_text",
    "measured_text",
    "png_size",
    "shortfall",
    "write_page",
]

CSS = """
:root { --ok: #1a7f37; --bad: #c62828; --ink: #1f2328; --muted: #59636e; --line: #d0d7de; --soft: #f6f8fa; }
* { box-sizing: border-box; }
body { font: 15px/1.5 system-ui, -apple-system, "Segoe UI", Roboto, "Helvetica Neue", Arial, sans-serif;
       color: var(--ink); margin: 0; background: #fff; }
main { max-width: 1000px; margin: 0 auto; padding: 24px 20px 60px; }
h1 { font-size: 1.6em; margin: 0 0 4px; }
h2 { font-size: 1.25em; margin: 36px 0 10px; padding-bottom: 4px; border-bottom: 1px solid var(--line); }
h3 { font-size: 1.05em; margin: 18px 0 6px; }
.sub { color: var(--muted); margin: 0 0 12px; }
.badge { display: inline-block; padding: 2px 12px; border-radius: 12px; color: #fff; font-weight: 600;
         letter-spacing: .04em; vertical-align: middle; font-size: .8em; }
.badge.pass { background: var(--ok); } .badge.fail { background: var(--bad); }
nav { font-size: .92em; color: var(--muted); } nav a { color: inherit; margin-right: 12px; }
table { border-collapse: collapse; width: 100%; margin: 8px 0 12px; font-size: .92em; }
th, td { border: 1px solid var(--line); padding: 5px 8px; text-align: left; vertical-align: top; }
th { background: var(--soft); font-weight: 600; }
td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
tr.fail td { background: #fff5f5; } td.pass { color: var(--ok); font-weight: 600; }
td.fail { color: var(--bad); font-weight: 700; }
section.failures { border: 2px solid var(--bad); background: #fff5f5; border-radius: 6px; padding: 4px 18px 12px;
                   margin: 20px 0; }
section.failures h2 { color: var(--bad); border-color: #f1b5b5; margin-top: 12px; }
section.failures .cause { font-weight: 600; }
section.allpass { border: 2px solid var(--ok); background: #f3fbf5; border-radius: 6px; padding: 8px 18px; margin: 20px 0; }
figure { margin: 22px 0; } figure img { max-width: 100%; height: auto; border: 1px solid var(--line); }
figcaption { margin-top: 6px; font-size: .93em; } figcaption .file { color: var(--muted); font-family: monospace; }
.note { border-left: 4px solid #d4a72c; background: #fff8e5; padding: 6px 12px; margin: 12px 0; font-size: .93em; }
pre { background: var(--soft); border: 1px solid var(--line); padding: 10px 12px; overflow-x: auto; font-size: .9em; }
code { font-family: ui-monospace, SFMono-Regular, Menlo, Consolas, monospace; }
footer { margin-top: 40px; color: var(--muted); font-size: .85em; }
"""


def esc(value: Any) -> str:
    """HTML-escape ``str(value)`` (quotes too, so it is safe inside attributes)."""
    return html.escape(str(value), quote=True)


def png_size(data: bytes) -> tuple[int, int]:
    """(width, height) in pixels from a PNG's IHDR chunk."""
    if data[:8] != b"\x89PNG\r\n\x1a\n" or data[12:16] != b"IHDR":
        raise ValueError("not a PNG file")
    return struct.unpack(">II", data[16:24])


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


def _cause(test: Mapping[str, Any]) -> Mapping[str, Any]:
    return test.get("cause") or {}


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


def _table(header: Iterable[str], rows: Iterable[str]) -> str:
    head = "".join(f"<th>{esc(h)}</th>" for h in header)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(rows)}</tbody></table>"


def confidence_statement(summary: Mapping[str, Any]) -> str:
    """What the page's verdict means: each check's level and the verdict's family-wise false-alarm bound."""
    confidence, checks = summary["confidence"], len(summary["tests"])
    bound = verdict_false_alarm_bound(confidence, checks)
    return (
        f"each check at {fmt(100 * confidence)}% confidence (a correct filter fails it with probability at most "
        f"{fmt(100 * (1 - confidence))}%); a correct filter fails at least one of the {checks} checks with "
        f"probability at most {fmt(100 * bound)}% (Bonferroni)"
    )


def _failures(summary: Mapping[str, Any]) -> str:
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
        lead = (
            f'<p class="cause">Likely cause: {esc(reason.rstrip("."))}.</p>'
            if reason
            else '<p class="cause">Likely cause: not identified by the check; see the figures below.</p>'
        )
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


def _verdicts(summary: Mapping[str, Any]) -> str:
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
        + _table(("check", "statistic", "bounds", "passed", "detail"), rows)
    )


def _setting(section: str, value: Any) -> str:
    if value is None:
        return "not set (the truth's value)" if section == "filter" else "not set"
    return fmt(value, 6)


def _settings(summary: Mapping[str, Any]) -> str:
    rows = []
    for section, values in summary.get("settings", {}).items():
        for key, value in values.items():
            rows.append(
                f"<tr><td><code>{esc(section)}.{esc(key)}</code></td><td>{esc(_setting(section, value))}</td></tr>"
            )
    run = [
        ("scenario", summary["scenario"]),
        ("realizations N", summary["realizations"]),
        ("seed", summary["seed"]),
        ("engine", summary["engine"]),
        ("update form", summary.get("form", "joseph")),
        ("confidence", summary["confidence"]),
    ]
    run_rows = [f"<tr><td>{esc(k)}</td><td>{esc(fmt(v, 6))}</td></tr>" for k, v in run]
    cause = summary.get("model_error", {}).get("cause")
    note = f'<p class="note">Deterministic model error in this scenario: {esc(cause)}.</p>' if cause else ""
    return (
        '<h2 id="scenario">Scenario and parameters</h2>'
        + _table(("run", "value"), run_rows)
        + _table(("setting", "value"), rows)
        + note
    )


def _final(summary: Mapping[str, Any]) -> str:
    final = summary.get("final")
    if not final:
        return ""
    rows = []
    for i, (name, unit) in enumerate(zip(final["states"], final["units"])):
        filt = final["filter_covariance"][i][i]
        ens = final["ensemble_covariance"][i][i]
        rows.append(
            f"<tr><td>{esc(name)}</td><td>{esc(unit)}</td><td class='num'>{esc(fmt(final['ensemble_mean_error'][i]))}</td>"
            f"<td class='num'>{esc(fmt(None if filt is None else filt**0.5))}</td>"
            f"<td class='num'>{esc(fmt(None if ens is None else ens**0.5))}</td></tr>"
        )
    return f"<h3>At the last update, t = {esc(fmt(final['time']))} s</h3>" + _table(
        ("state", "unit", "ensemble mean error", "filter σ = √P_ii", "ensemble σ"), rows
    )


def _residual_pair(summary: Mapping[str, Any]) -> str:
    pair = summary.get("residual_correlation")
    if not pair:
        return ""
    rows = []
    for a, (row, corr, se) in enumerate(zip(pair["matrix"], pair["correlation"], pair["standard_error"])):
        cells = "".join(
            f"<td class='num'>{esc(fmt(m))} ± {esc(fmt(s, 2))} (ρ = {esc(fmt(c, 2))})</td>" for m, c, s in zip(row, corr, se)
        )
        rows.append(f"<tr><td>row {a + 1}</td>{cells}</tr>")
    header = ["E[r_k r_jᵀ]"] + [f"column {b + 1}" for b in range(len(pair["matrix"][0]))]
    return (
        f"<h3>E[r_k r_jᵀ] at t_k = {esc(fmt(pair['k_time']))} s, t_j = {esc(fmt(pair['j_time']))} s</h3>"
        "<p class='sub'>The pair the source report quotes; each entry ± its standard error, with the correlation ρ.</p>"
        + _table(header, rows)
    )


def _figure(entry: FigureEntry, figure_dir_name: str) -> str:
    data = entry.path.read_bytes()
    width, height = png_size(data)
    uri = "data:image/png;base64," + base64.b64encode(data).decode("ascii")
    number = f"Figure {entry.number}. " if entry.number else ""
    file = f"{figure_dir_name}/{entry.path.name}"
    return (
        f'<figure id="fig-{esc(entry.key)}"><img src="{uri}" width="{width}" height="{height}" '
        f'alt="{esc(entry.title)}" data-file="{esc(file)}">'
        f"<figcaption><strong>{esc(number)}{esc(entry.title)}.</strong> {esc(entry.caption)} "
        f'<span class="file">{esc(file)}</span></figcaption></figure>'
    )


def _skipped(entry: SkippedFigure) -> str:
    number = f"Figure {entry.number} ({entry.title})" if entry.number else f"The figure {entry.title}"
    return (
        f'<p class="note" id="fig-{esc(entry.key)}"><strong>{esc(number)} is not shown:</strong> '
        f"{esc(entry.reason)}.</p>"
    )


def _steady_state(view: SteadyStateView | None) -> str:
    """The steady state's table beside the time-varying filter (nothing when there are no matrices: the
    skipped figure's note says why)."""
    if view is None or not view.has_matrices:
        return ""
    result, progress = view.result, view.convergence
    last = view.posterior_cov[-1]
    intro = (
        "<p class='sub'>From the discrete algebraic Riccati equation over one update interval "
        "(<code>scipy.linalg.solve_discrete_are</code>), beside the time-varying filter at its last update; "
        f"spectral radius of Φ(I − K∞H): {esc(fmt(result.spectral_radius))}.</p>"
    )
    if not result.stabilizing:
        intro += (
            f'<p class="note"><strong>No stabilizing solution:</strong> {esc(result.reason)}. The values below are '
            "the solution scipy returned; P_k approaches it only in the states the noise reaches.</p>"
        )
    elif progress is not None:
        tolerance = fmt(progress.tolerance)
        if progress.update is None:
            intro += (
                f"<p>P_k does not settle within {esc(tolerance)} of P∞ (relative Frobenius norm) within the run: the "
                f"gap at the last update is {esc(fmt(float(progress.relative_gap[-1]), 3))}.</p>"
            )
        else:
            intro += (
                f"<p>P_k stays within {esc(tolerance)} of P∞ (‖P_k − P∞‖ / ‖P∞‖, Frobenius) from update "
                f"{esc(progress.update + 1)} of {esc(len(view.times))}, t = {esc(fmt(view.converged_time()))} s.</p>"
            )
    rows = []
    for i, (name, unit) in enumerate(zip(view.state_names, view.state_units)):
        if progress is None:
            settled = "—"
        elif progress.state_update[i] is None:
            settled = "not within the run"
        else:
            k = progress.state_update[i]
            settled = f"update {k + 1}, t = {fmt(float(view.times[k]))} s"
        gains = ", ".join(fmt(float(g), 4) for g in result.gain[i])
        cells = (
            fmt(float(np.sqrt(max(result.posterior_cov[i, i], 0.0)))),
            fmt(float(np.sqrt(max(last[i, i], 0.0)))),
            fmt(float(np.sqrt(max(result.prior_cov[i, i], 0.0)))),
        )
        rows.append(
            f"<tr><td>{esc(name)}</td><td>{esc(unit)}</td>"
            + "".join(f"<td class='num'>{esc(c)}</td>" for c in cells)
            + f"<td class='num'>{esc(gains)}</td><td>{esc(settled)}</td></tr>"
        )
    within = f"P_ii within {fmt(progress.tolerance)} of P∞,ii from" if progress is not None else "P_ii settles"
    header = ("state", "unit", "σ∞ = √P∞,ii", "σ_k at the last update", "prior σ∞ = √M∞,ii", "row of K∞", within)
    return intro + _table(header, rows)


def _figures(
    summary,
    figures: list[FigureEntry],
    skipped: list[SkippedFigure],
    realization: int,
    figure_dir_name: str,
    steady: SteadyStateView | None = None,
) -> str:
    parts = ['<h2 id="figures">Figures</h2>']
    for group, heading in GROUPS:
        members = [f for f in figures if f.group == group]
        missing = [s for s in skipped if s.group == group]
        if not members and not missing:
            continue
        intro = ""
        if group == "realization":
            intro = (
                f"<p class='sub'>Realization {realization} of the {fmt(summary['realizations'])}, redrawn from the "
                f"run's seed {esc(summary['seed'])} (the same draws as in the ensemble).</p>"
            )
        body = "".join(_figure(f, figure_dir_name) for f in members) + "".join(_skipped(s) for s in missing)
        if group == "consistency":
            body += _residual_pair(summary)
        if group == "steady_state":
            body = _steady_state(steady) + body
        parts.append(f'<h3 id="group-{esc(group)}">{esc(heading)}</h3>{intro}{body}')
    return "".join(parts)


def _timing(summary: Mapping[str, Any]) -> str:
    timing = summary.get("timing", {})
    labels = {
        "monte_carlo_s": "Monte Carlo wall time (s)",
        # verify's time up to summary.json; drawing this page is not in it (the page holds no time of
        # its own drawing, so that redrawing it gives the same bytes)
        "total_s": "wall time of the verification up to summary.json: Monte Carlo, long run, checks, statistics files; not the report (s)",
        "realizations_per_s": "realizations per second",
        "workers": "worker threads",
        "normals_per_realization": "standard normals drawn per realization",
    }
    # report_s and wall_s (the whole job, this page included) are measured after the page is drawn: the
    # page shows neither, whether drawn by verify or redrawn later, and says where they are
    known = {k: v for k, v in timing.items() if k not in ("report_s", "wall_s")}
    rows = [f"<tr><td>{esc(labels.get(k, k))}</td><td class='num'>{esc(fmt(v))}</td></tr>" for k, v in known.items()]
    long_run = summary.get("long_run")
    if long_run:
        rows.append(
            f"<tr><td>long run: {esc(fmt(long_run.get('duration')))} s × {esc(fmt(long_run.get('realizations')))} "
            f"realizations, wall time (s)</td><td class='num'>{esc(fmt(long_run.get('monte_carlo_s')))}</td></tr>"
        )
    note = (
        "<p>The whole job's wall time, this report included, is known only after the page is drawn: "
        "summary.json holds it as timing.wall_s, and the report's own time as timing.report_s.</p>"
    )
    return '<h2 id="timing">Timing</h2>' + _table(("quantity", "value"), rows) + note


def _reproduce(summary: Mapping[str, Any], realization: int) -> str:
    command = summary.get("command") or ""
    shown = (
        f"<pre><code>{esc(command)}</code></pre>"
        if command
        else "<p>The command was not recorded in summary.json; rerun <code>kalcal verify</code> with the settings above.</p>"
    )
    return (
        '<h2 id="reproduce">Reproduce</h2><p>The exact command of this run (same seed, same numbers):</p>'
        + shown
        + "<p>Redraw this page and its figures from the saved statistics, without rerunning the Monte Carlo:</p>"
        + f"<pre><code>kalcal report RUN_DIRECTORY --realization {esc(realization)}</code></pre>"
    )


def build_page(
    summary: Mapping[str, Any],
    figures: list[FigureEntry],
    skipped: list[SkippedFigure] = (),
    *,
    realization: int = 0,
    figure_dir_name: str = "figures",
    steady_state: SteadyStateView | None = None,
) -> str:
    """The report page as one HTML string.

    Parameters
    ----------
    summary : mapping
        The run's ``summary.json``.
    figures : list of FigureEntry
        Drawn figures, in page order; their PNGs are read and embedded.
    skipped : list of SkippedFigure
        Figures this run cannot show, each with a note.
    realization : int
        Index of the realization drawn in the single-run figures.
    figure_dir_name : str
        Folder of the PNG files relative to the page (named in each caption).
    steady_state : SteadyStateView, optional
        The filter's steady state, tabled beside its figure.
    """
    verdict = "pass" if all(t["passed"] for t in summary["tests"]) else "fail"
    title = f"kalcal verification report: {summary['scenario']}"
    header = (
        f'<h1>{esc(title)} <span class="badge {verdict}">{verdict.upper()}</span></h1>'
        f"<p class='sub'>{esc(fmt(summary['realizations']))} realizations ({esc(summary['engine'])} engine), seed "
        f"{esc(summary['seed'])}; {esc(confidence_statement(summary))}; "
        f"kalcal {esc(summary.get('kalcal_version', ''))}.</p>"
        '<nav><a href="#failures">failures</a><a href="#verdicts">verdicts</a><a href="#scenario">scenario</a>'
        '<a href="#figures">figures</a><a href="#timing">timing</a><a href="#reproduce">reproduce</a></nav>'
    )
    body = (
        header
        + _failures(summary)
        + _verdicts(summary)
        + _settings(summary)
        + _final(summary)
        + _figures(summary, list(figures), list(skipped), realization, figure_dir_name, steady_state)
        + _timing(summary)
        + _reproduce(summary, realization)
        + f"<footer>Written by kalcal {esc(summary.get('kalcal_version', ''))} from summary.json and stats.nc.</footer>"
    )
    return (
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
        '<meta name="viewport" content="width=device-width, initial-scale=1">\n'
        f"<title>{esc(title)}</title>\n<style>{CSS}</style>\n</head>\n<body>\n<main>\n{body}\n</main>\n</body>\n</html>\n"
    )


def write_page(path: str | Path, page: str) -> Path:
    """Write the page atomically (a reader never sees half a file)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(path.name + ".tmp")
    temporary.write_text(page, encoding="utf-8")
    os.replace(temporary, path)
    return path
