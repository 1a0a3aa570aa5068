"""The page's figures section: embedded PNGs with captions, notes for skipped figures, and the tables beside them."""

from __future__ import annotations

import base64
import struct
from collections.abc import Mapping
from typing import Any

import numpy as np

from kalcal.reporting.figure_entries import GROUPS, FigureEntry, SkippedFigure
from kalcal.reporting.markup import esc, table
from kalcal.filters.steady_state import SteadyStateView
from kalcal.stats.text import fmt

__all__ = ["figures_section", "png_size", "residual_pair_table"]


def png_size(data: bytes) -> tuple[int, int]:
    """(width, height) in pixels from a PNG's IHDR chunk."""
    if data[:8] != b"\x89PNG\r\n\x1a\n" or data[12:16] != b"IHDR":
        raise ValueError("not a PNG file")
    return struct.unpack(">II", data[16:24])


def residual_pair_table(summary: Mapping[str, Any]) -> str:
    """The report's E[r_k r_j^T] pair with standard errors and correlations (empty where the run has none)."""
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
        + table(header, rows)
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
    return intro + table(header, rows)


def figures_section(
    summary: Mapping[str, Any],
    figures: list[FigureEntry],
    skipped: list[SkippedFigure],
    realization: int,
    figure_dir_name: str,
    steady: SteadyStateView | None = None,
) -> str:
    """Every figure group in page order: its drawn figures, notes for those skipped, and its tables."""
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
            body += residual_pair_table(summary)
        if group == "steady_state":
            body = _steady_state(steady) + body
        parts.append(f'<h3 id="group-{esc(group)}">{esc(heading)}</h3>{intro}{body}')
    return "".join(parts)
