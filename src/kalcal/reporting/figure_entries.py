"""The report's figures as the page lists them: their groups, the figures drawn and those skipped.

Data only, without matplotlib: the page is built in a process that need not load the plotting code.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

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
