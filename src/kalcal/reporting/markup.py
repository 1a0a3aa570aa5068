"""HTML building blocks of the page: escaping text and writing a table."""

from __future__ import annotations

import html
from collections.abc import Iterable
from typing import Any

__all__ = ["esc", "table"]


def esc(value: Any) -> str:
    """HTML-escape ``str(value)`` (quotes too, so it is safe inside attributes)."""
    return html.escape(str(value), quote=True)


def table(header: Iterable[str], rows: Iterable[str], *, css_class: str = "", table_id: str = "") -> str:
    """A table with the (escaped) ``header`` cells over ``rows``, already written as ``<tr>`` HTML;
    ``css_class`` and ``table_id`` its class and id, where given."""
    head = "".join(f"<th>{esc(h)}</th>" for h in header)
    attributes = (f' class="{esc(css_class)}"' if css_class else "") + (f' id="{esc(table_id)}"' if table_id else "")
    return f"<table{attributes}><thead><tr>{head}</tr></thead><tbody>{''.join(rows)}</tbody></table>"
