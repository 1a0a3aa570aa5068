"""The page's sections on the run itself: scenario and parameters, the last update, timing, reproducing it."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from kalcal.reporting.markup import esc, table
from kalcal.stats.text import fmt

__all__ = ["final_table", "reproduce_section", "settings_section", "timing_section"]


def _setting(section: str, value: Any) -> str:
    if value is None:
        return "not set (the truth's value)" if section == "filter" else "not set"
    return fmt(value, 6)


def settings_section(summary: Mapping[str, Any]) -> str:
    """The run's identity (scenario, N, seed, engine, form, confidence), the model-error note, and every
    setting (folded)."""
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
        + table(("run", "value"), run_rows)
        + note
        # the settings are long (40 rows for accel-gps): folded under their count
        + f"<details><summary>All {len(rows)} settings</summary>"
        + table(("setting", "value"), rows)
        + "</details>"
    )


def final_table(summary: Mapping[str, Any]) -> str:
    """Ensemble mean error, filter and ensemble standard deviations per state at the last update, and the exact
    one where the run has an exact analysis (empty without them)."""
    final = summary.get("final")
    if not final:
        return ""
    rows = []
    exact = final.get("exact_error_covariance")  # the exact analysis's P_true: none for scale-bias or older runs
    for i, (name, unit) in enumerate(zip(final["states"], final["units"])):
        filt = final["filter_covariance"][i][i]
        ens = final["ensemble_covariance"][i][i]
        true = None if exact is None else exact[i][i]
        rows.append(
            f"<tr><td>{esc(name)}</td><td>{esc(unit)}</td><td class='num'>{esc(fmt(final['ensemble_mean_error'][i]))}</td>"
            f"<td class='num'>{esc(fmt(None if filt is None else filt**0.5))}</td>"
            f"<td class='num'>{esc(fmt(None if ens is None else ens**0.5))}</td>"
            + ("" if exact is None else f"<td class='num'>{esc(fmt(None if true is None else max(true, 0.0) ** 0.5))}</td>")
            + "</tr>"
        )
    header = ("state", "unit", "ensemble mean error", "filter σ = √P_ii", "ensemble σ")
    return f"<h3>At the last update, t = {esc(fmt(final['time']))} s</h3>" + table(
        header + (() if exact is None else ("exact σ = √P_true,ii",)), rows
    )


def timing_section(summary: Mapping[str, Any]) -> str:
    """The recorded wall times and rates, and where the job's and page's own times are."""
    timing = summary.get("timing", {})
    labels = {
        "monte_carlo_s": "Monte Carlo wall time (s)",
        "long_run_s": "long-run study's Monte Carlo wall time (s)",
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
    return '<h2 id="timing">Timing</h2>' + table(("quantity", "value"), rows) + note


def reproduce_section(summary: Mapping[str, Any], realization: int) -> str:
    """The run's exact command and the command that redraws this page."""
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
