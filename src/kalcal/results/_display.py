"""What the result objects share for display: an interval's level from ``alpha`` or ``level``, and escaped HTML tables."""

from __future__ import annotations

import html
import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from kalcal.errors import KalcalError


def level_of(alpha: float | None, level: float | None, default: float) -> float:
    """The confidence level asked for: ``level``, or ``1 - alpha`` (statsmodels' ``conf_int(alpha)``), or
    ``default``; refuses both given and a level outside (0, 1) (a :class:`~kalcal.errors.KalcalError`,
    a ValueError)."""
    if alpha is not None and level is not None:
        raise KalcalError(f"conf_int: give alpha or level, not both (got alpha={alpha!r}, level={level!r})")
    if alpha is not None:
        if not _number(alpha) or not 0.0 < alpha < 1.0:
            raise KalcalError(f"conf_int: alpha: expected a number in (0, 1), got {alpha!r}")
        return 1.0 - float(alpha)
    if level is None:
        return float(default)
    if not _number(level) or not 0.0 < level < 1.0:
        raise KalcalError(f"conf_int: level: expected a number in (0, 1), got {level!r}")
    return float(level)


def _number(value: Any) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool) and math.isfinite(value)


def same_level(a: float, b: float) -> bool:
    """Whether two levels are the same one (0.95 given as 1 - 0.05 is 0.95)."""
    return abs(a - b) <= 1e-12


def fmt(value: Any, digits: int = 4) -> str:
    """A number in ``digits`` significant figures; None and NaN as a dash; anything else as text."""
    if value is None:
        return "—"
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return "—" if math.isnan(value) else f"{float(value):.{digits}g}"
    return str(value)


def html_table(header: Sequence[str], rows: Iterable[Sequence[Any]]) -> str:
    """An HTML table, every cell escaped (numbers through :func:`fmt`)."""
    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(fmt(cell))}</td>" for cell in row) + "</tr>" for row in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def html_facts(title: str, facts: Iterable[tuple[str, Any]]) -> str:
    """A bold ``title`` and ``name: value`` facts on one line, escaped."""
    text = ", ".join(f"{html.escape(name)} {html.escape(fmt(value))}" for name, value in facts)
    return f"<b>{html.escape(title)}</b>" + (f": {text}" if text else "")


def text_table(header: Sequence[str], rows: Sequence[Sequence[Any]], digits: int = 4) -> list[str]:
    """A plain-text table: the first column left-aligned, the others right-aligned."""
    cells = [list(header), *[[fmt(cell, digits) for cell in row] for row in rows]]
    widths = [max(len(row[i]) for row in cells) for i in range(len(header))]

    def line(row):
        return "  ".join(cell.ljust(w) if i == 0 else cell.rjust(w) for i, (cell, w) in enumerate(zip(row, widths))).rstrip()

    return [line(cells[0]), "-" * sum(widths) + "-" * 2 * (len(widths) - 1), *(line(row) for row in cells[1:])]
