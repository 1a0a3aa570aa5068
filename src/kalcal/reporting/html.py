"""``report.html``: the page template filled with the run's sections, and writing it atomically.

The page loads nothing from outside: figures are PNG data URIs, the style (``templates/report.css``) is
inline, there is no script. It holds no time stamp, so the same run directory always gives the same bytes.
Every piece of text that comes from the run (settings, check details, the command) is HTML-escaped: the
sections escape their own text (:func:`kalcal.reporting.markup.esc`) and enter the template as markup; the
template's autoescaping escapes the values it is given.

The page leads with its answer (:mod:`kalcal.reporting.answer`): the verdict in one sentence with its
cause, a row per check and the three or four figures that show it; the detail, power, settings and
self-check follow, folded where long (``<details>``), then the other figures.

Its figures section lives here too: the figures as the page lists them (:class:`FigureEntry`,
:class:`SkippedFigure`, their groups and order; data only, without matplotlib, so that the page is built
in a process that need not load the plotting code) and their markup (embedded PNGs with captions, notes
for skipped figures, and the tables beside them). Which figures a run gets is :mod:`kalcal.reporting.figures`'.
"""

from __future__ import annotations

import base64
import functools
import os
import struct
from collections.abc import Mapping
from dataclasses import dataclass
from importlib import resources
from importlib.resources.abc import Traversable
from pathlib import Path
from typing import Any

import jinja2
import numpy as np
from markupsafe import Markup

from kalcal.filters.steady_state import SteadyStateView
from kalcal.reporting.answer import answer as page_answer
from kalcal.reporting.answer import lead_figures
from kalcal.reporting.markup import esc, table
from kalcal.reporting.run_tables import final_table, reproduce_section, settings_section, timing_section
from kalcal.reporting.text import confidence_statement, scope_statement
from kalcal.reporting.theory import power_section, self_check_section
from kalcal.reporting.verdicts import answer_section, checks_table, effects_section, failures_section, left_out_note, verdicts_section
from kalcal.stats.text import fmt

GROUPS = (
    ("realization", "One realization"),
    ("ensemble", "Ensemble statistics"),
    ("consistency", "Consistency, whiteness and model error"),
    ("steady_state", "Steady state"),
)


@dataclass(frozen=True)
class FigureEntry:
    """One drawn figure: ``path`` is its PNG; ``number`` the source report's figure number, if any."""

    key: str
    group: str
    title: str
    caption: str
    path: Path
    number: str | None = None


@dataclass(frozen=True)
class SkippedFigure:
    """A figure that could not be drawn from this run, and why."""

    key: str
    group: str
    title: str
    reason: str
    number: str | None = None


#: the figures of the realization shown, per state of the filter: its state and its estimation error
REALIZATION_FIGURES_PER_STATE = 2


def sort_key(item: FigureEntry | SkippedFigure) -> tuple:
    """Report figures in the report's order, then the rest in catalog order (stable sort keeps it)."""
    if item.number is None:
        return (1, 0, 0)
    major, minor = item.number.split(".")
    return (0, int(major), int(minor))


def page_order(figures: list[FigureEntry]) -> list[FigureEntry]:
    """Figures in the page's order: the source report's by number, then the rest in the order given
    (the realization's, then the statistics': :func:`kalcal.reporting.figures.render_figures`'s order
    for the two lists of its parts joined)."""
    return sorted(figures, key=sort_key)





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


def _figure_label(entry: FigureEntry) -> str:
    """``Figure 5.7 (title)``, or the title alone for a figure without a report number."""
    return f"Figure {entry.number} ({entry.title})" if entry.number else entry.title


def lead_section(figures: list[FigureEntry], figure_dir_name: str) -> str:
    """The figures that show the answer, in one row under it (empty without any).

    Up to four fit one row of the first screen, each with its caption folded under its title, so the row's
    height is the tallest image plus a title; a click on an image shows it full size over the page (the
    page's CSS on the figure as the link's target: no script, and the page stays one file).
    """
    if not figures:
        return ""
    return '<div class="lead-figures">' + "".join(_figure(f, figure_dir_name, lead=True) for f in figures) + "</div>"


def _figure(entry: FigureEntry, figure_dir_name: str, lead: bool = False) -> str:
    """A figure with its PNG embedded; a ``lead`` one links to itself (enlarged) and folds its caption."""
    data = entry.path.read_bytes()
    width, height = png_size(data)
    uri = "data:image/png;base64," + base64.b64encode(data).decode("ascii")
    number = f"Figure {entry.number}. " if entry.number else ""
    file = f"{figure_dir_name}/{entry.path.name}"
    image = (
        f'<img src="{uri}" width="{width}" height="{height}" alt="{esc(entry.title)}" data-file="{esc(file)}">'
    )
    title = f"<strong>{esc(number)}{esc(entry.title)}.</strong>"
    caption = f'{esc(entry.caption)} <span class="file">{esc(file)}</span>'
    if lead:
        return (
            f'<figure id="fig-{esc(entry.key)}"><a href="#fig-{esc(entry.key)}" title="enlarge">{image}</a>'
            f"<figcaption><details><summary>{title}</summary>{caption}</details></figcaption>"
            '<a class="close" href="#answer">close</a></figure>'
        )
    return f'<figure id="fig-{esc(entry.key)}">{image}<figcaption>{title} {caption}</figcaption></figure>'


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
    shown: frozenset[str] = frozenset(),
) -> str:
    """Every figure group in page order: its drawn figures, notes for those skipped, and its tables; a
    figure whose key is in ``shown`` leads the page already, and its group links to it instead."""
    parts = ['<h2 id="figures">Figures</h2>']
    for group, heading in GROUPS:
        members = [f for f in figures if f.group == group]
        missing = [s for s in skipped if s.group == group]
        if not members and not missing:
            continue
        above = [f for f in members if f.key in shown]
        members = [f for f in members if f.key not in shown]
        intro = ""
        if group == "realization":
            intro = (
                f"<p class='sub'>Realization {realization} of the {fmt(summary['realizations'])}, redrawn from the "
                f"run's seed {esc(summary['seed'])} (the same draws as in the ensemble).</p>"
            )
        body = "".join(_figure(f, figure_dir_name) for f in members) + "".join(_skipped(s) for s in missing)
        if above:
            links = ", ".join(f'<a href="#fig-{esc(f.key)}">{esc(_figure_label(f))}</a>' for f in above)
            intro += f"<p class='sub'>Shown at the top of the page: {links}.</p>"
        if group == "consistency":
            body += residual_pair_table(summary)
        if group == "steady_state":
            body = _steady_state(steady) + body
        parts.append(f'<h3 id="group-{esc(group)}">{esc(heading)}</h3>{intro}{body}')
    return "".join(parts)


__all__ = [
    "CSS_FILE",
    "GROUPS",
    "PAGE_TEMPLATE",
    "FigureEntry",
    "SkippedFigure",
    "build_page",
    "figures_section",
    "lead_section",
    "page_css",
    "page_order",
    "png_size",
    "residual_pair_table",
    "write_page",
]

#: the page's skeleton and its style: package data of :mod:`kalcal.reporting`, under ``templates/``
PAGE_TEMPLATE = "page.html.j2"
CSS_FILE = "report.css"


def _templates() -> Traversable:
    return resources.files("kalcal.reporting").joinpath("templates")


@functools.cache
def _environment() -> jinja2.Environment:
    return jinja2.Environment(
        loader=jinja2.FunctionLoader(lambda name: _templates().joinpath(name).read_text(encoding="utf-8")),
        autoescape=True,
        # the template's values escaped as the sections escape theirs (``&#x27;``, not markupsafe's ``&#39;``):
        # one spelling of every escaped character across the page
        finalize=lambda value: value if isinstance(value, Markup) else Markup(esc(value)),
        undefined=jinja2.StrictUndefined,
        keep_trailing_newline=True,
    )


@functools.cache
def page_css() -> str:
    """The page's style sheet (``templates/report.css``), inlined into every page."""
    return _templates().joinpath(CSS_FILE).read_text(encoding="utf-8")


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
    figures = list(figures)
    answer = page_answer(summary)
    lead_keys = lead_figures(answer.figures, [f.key for f in figures])
    lead = sorted((f for f in figures if f.key in lead_keys), key=lambda f: lead_keys.index(f.key))
    # (anchor the navigation links to, its label, the section): a section a run lacks is left out, link too
    sections = (
        ("failures", "failures", failures_section(summary, answer)),
        ("verdicts", "verdicts", verdicts_section(summary)),
        ("effects", "effect sizes", effects_section(summary)),
        ("power", "power", power_section(summary)),
        ("scenario", "settings", settings_section(summary)),
        ("", "", final_table(summary)),
        ("self-check", "self-check", self_check_section(summary)),
        (
            "figures",
            "figures",
            figures_section(
                summary, figures, list(skipped), realization, figure_dir_name, steady_state, frozenset(lead_keys)
            ),
        ),
        ("timing", "timing", timing_section(summary)),
        ("reproduce", "reproduce", reproduce_section(summary, realization)),
    )
    return _environment().get_template(PAGE_TEMPLATE).render(
        title=f"kalcal verification report: {summary['scenario']}",
        verdict=answer.verdict,
        answer=Markup(answer_section(answer, scope_statement(summary))),
        checks=Markup(checks_table(answer) + left_out_note(summary)),
        lead=Markup(lead_section(lead, figure_dir_name)),
        realizations=fmt(summary["realizations"]),
        engine=summary["engine"],
        seed=summary["seed"],
        statement=confidence_statement(summary),
        version=summary.get("kalcal_version", ""),
        css=Markup(page_css()),
        # each section escapes the run's text it holds: marked as markup so it is not escaped twice
        nav=[(anchor, label) for anchor, label, section in sections if anchor and section],
        sections=[Markup(section) for _, _, section in sections],
    )


def write_page(path: str | Path, page: str) -> Path:
    """Write the page atomically (a reader never sees half a file)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(path.name + ".tmp")
    temporary.write_text(page, encoding="utf-8")
    os.replace(temporary, path)
    return path
