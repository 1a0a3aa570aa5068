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
