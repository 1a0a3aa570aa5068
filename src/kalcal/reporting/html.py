"""``report.html``: the page template filled with the run's sections, and writing it atomically.

The page loads nothing from outside: figures are PNG data URIs, the style (``templates/report.css``) is
inline, there is no script. It holds no time stamp, so the same run directory always gives the same bytes.
Every piece of text that comes from the run (settings, check details, the command) is HTML-escaped: the
sections escape their own text (:func:`kalcal.reporting.markup.esc`) and enter the template as markup; the
template's autoescaping escapes the values it is given.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Mapping
from importlib import resources
from importlib.resources.abc import Traversable
from pathlib import Path
from typing import Any

import jinja2
from markupsafe import Markup

from kalcal.reporting.figure_html import figures_section
from kalcal.reporting.figure_entries import FigureEntry, SkippedFigure
from kalcal.reporting.markup import esc
from kalcal.reporting.run_tables import final_table, reproduce_section, settings_section, timing_section
from kalcal.filters.steady_state import SteadyStateView
from kalcal.reporting.text import confidence_statement, scope_statement
from kalcal.reporting.theory import power_section, self_check_section
from kalcal.reporting.verdicts import failures_section, verdicts_section
from kalcal.stats.text import fmt

__all__ = ["CSS_FILE", "PAGE_TEMPLATE", "build_page", "page_css", "write_page"]

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
    sections = (
        failures_section(summary),
        verdicts_section(summary),
        power_section(summary),
        settings_section(summary),
        final_table(summary),
        self_check_section(summary),
        figures_section(summary, list(figures), list(skipped), realization, figure_dir_name, steady_state),
        timing_section(summary),
        reproduce_section(summary, realization),
    )
    return _environment().get_template(PAGE_TEMPLATE).render(
        title=f"kalcal verification report: {summary['scenario']}",
        verdict="pass" if all(t["passed"] for t in summary["tests"]) else "fail",
        realizations=fmt(summary["realizations"]),
        engine=summary["engine"],
        seed=summary["seed"],
        statement=confidence_statement(summary),
        scope=scope_statement(summary),
        version=summary.get("kalcal_version", ""),
        css=Markup(page_css()),
        # each section escapes the run's text it holds: marked as markup so it is not escaped twice
        sections=[Markup(section) for section in sections],
    )


def write_page(path: str | Path, page: str) -> Path:
    """Write the page atomically (a reader never sees half a file)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(path.name + ".tmp")
    temporary.write_text(page, encoding="utf-8")
    os.replace(temporary, path)
    return path
