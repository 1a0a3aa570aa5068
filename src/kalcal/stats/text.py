"""Check results in words, as the report page and the command line both show them.

One place for the bounds of a check (each part's, labelled), its p-value (with a NaN one named as
such) and the words for a cause's ``explained_by`` and ``direction``, so that the page and the
terminal say the same thing. Each function takes a check as it is in ``summary.json``'s ``tests``
list (a mapping; NaN and infinite values written as ``None``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from kalcal.errors import KalcalError
from kalcal.stats.results import DIRECTION_TEXT, EXPLAINED_BY_TEXT

#: how a check's parts are named in words
PART_LABELS = {
    "elements": "element-wise",
    "centered_nees": "centered NEES",
    "pairs": "pairs",
    "portmanteau": "portmanteau",
    "nis": "NIS",
    "ljung_box": "Ljung-Box",
    "nees": "NEES",
}
#: the keys of summary.json's ``nonfinite.fields`` that count NaN p-values: of the checks, of their parts
CHECK_PVALUE_FIELD, PART_PVALUE_FIELD = "tests.pvalue", "tests.parts.pvalue"


def fmt(value: Any, digits: int = 4) -> str:
    """A number with ``digits`` significant digits; ``None`` as an em dash; anything else as text."""
    if value is None:
        return "—"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return f"{value:,}"
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return str(value)


def bounds_text(test: Mapping[str, Any]) -> str:
    """``≤ upper`` for a one-sided test, ``[lower, upper]`` for a two-sided one."""
    if test.get("lower") is None:
        return f"≤ {fmt(test['upper'])}"
    return f"[{fmt(test['lower'])}, {fmt(test['upper'])}]"


def part_label(part: Mapping[str, Any]) -> str:
    """A part's name in words (its own name when it has none)."""
    return PART_LABELS.get(part["name"], part["name"])


def check_bounds_text(test: Mapping[str, Any]) -> str:
    """Every bound a check was held against: its own, or each part's, labelled."""
    parts = test.get("parts") or []
    if not parts:
        return bounds_text(test)
    return "; ".join(f"{part_label(part)} {bounds_text(part)}" for part in parts)


def pvalue_text(pvalue: Any, nan: bool = False) -> str:
    """``p = 0.0123``; ``p = NaN (not computable)`` for a NaN p-value, or a ``None`` one where ``nan``
    says the summary wrote a NaN there (its ``nonfinite.fields``, :func:`written_nan`); else, for
    ``None``, ``p not recorded``."""
    if isinstance(pvalue, float) and math.isnan(pvalue) or (pvalue is None and nan):
        return "p = NaN (not computable)"
    return "p not recorded" if pvalue is None else f"p = {fmt(pvalue, 3)}"


def written_nan(summary: Mapping[str, Any], key: str) -> bool:
    """Whether ``summary.json`` wrote a NaN (or infinite) value under the dotted ``key`` as ``null``.

    A p-value is never infinite, so for ``tests.pvalue`` or ``tests.parts.pvalue`` a ``null`` there is a
    NaN p-value (the count names the field, not the position in the list: every ``null`` p-value under
    a counted key is one)."""
    fields = (summary.get("nonfinite") or {}).get("fields") or {}
    return bool(fields.get(key))


def _words(table: Mapping[str, str], field: str, value: Any) -> str | None:
    if value is None:
        return None
    if value not in table:
        raise KalcalError(f"cause.{field}: unknown value {value!r} (expected one of {', '.join(table)} or null)")
    return table[value]


def explained_by_text(cause: Mapping[str, Any]) -> str | None:
    """What a cause's ``explained_by`` means, in words (None for none; an unknown value is an error)."""
    return _words(EXPLAINED_BY_TEXT, "explained_by", cause.get("explained_by"))


def direction_text(cause: Mapping[str, Any]) -> str | None:
    """What a cause's ``direction`` means, in words (None for none; an unknown value is an error)."""
    return _words(DIRECTION_TEXT, "direction", cause.get("direction"))
