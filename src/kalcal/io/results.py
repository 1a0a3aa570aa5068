"""Writers of results: JSON summaries and CSV tables, readable by any tool."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

#: Version of the layout of the JSON documents kalcal writes (``summary.json``, ``truth.json``): raised
#: whenever a key is removed or changes meaning, so that a reader can tell which layout it holds.
SCHEMA_VERSION = 1


def to_jsonable(value: Any, nonfinite: dict[str, int] | None = None, _path: str = "") -> Any:
    """numpy scalars and arrays to Python numbers and lists; non-finite floats to None (JSON has no NaN).

    Parameters
    ----------
    value : any
        A document of dicts, lists, tuples, numpy arrays and scalars.
    nonfinite : dict, optional
        If given, every NaN or infinity replaced by None is counted in it under its field's dotted path
        (``"final.filter_covariance"``, ``"tests.statistic"``): dict keys name the path, positions within
        lists and arrays do not.
    """
    if isinstance(value, dict):
        return {
            str(k): to_jsonable(v, nonfinite, f"{_path}.{k}" if _path else str(k)) for k, v in value.items()
        }
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v, nonfinite, _path) for v in value]
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist(), nonfinite, _path)
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.floating, float)):
        number = float(value)
        if math.isfinite(number):
            return number
        if nonfinite is not None:
            nonfinite[_path] = nonfinite.get(_path, 0) + 1
        return None
    return value


def json_document(document: dict[str, Any]) -> dict[str, Any]:
    """``document`` as :func:`write_json` writes it (and ``json.load`` reads it back): plain numbers and
    lists, NaN and infinities as None, ``schema_version`` first and ``nonfinite`` last (see there)."""
    nonfinite: dict[str, int] = {}
    body = to_jsonable({k: v for k, v in document.items() if k not in ("schema_version", "nonfinite")}, nonfinite)
    return {
        "schema_version": SCHEMA_VERSION,
        **body,
        "nonfinite": {"count": sum(nonfinite.values()), "fields": nonfinite},
    }


def write_json(path: str | Path, document: dict[str, Any]) -> Path:
    """Write ``document`` as indented JSON, atomically (write to a temporary file, then rename).

    The file gains two keys: ``schema_version`` (first, :data:`SCHEMA_VERSION`) and ``nonfinite`` (last):
    ``{"count": n, "fields": {dotted path: count}}``, the NaN and infinite values written as ``null``,
    so that a ``null`` in the file is never silent (``count`` is 0 and ``fields`` empty when there are none).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(path.name + ".tmp")
    temporary.write_text(json.dumps(json_document(document), indent=2) + "\n")
    os.replace(temporary, path)
    return path


def write_csv(path: str | Path, columns: dict[str, np.ndarray]) -> Path:
    """Write equal-length columns as a CSV table through pandas (``DataFrame.to_csv``, no index): floats in
    their shortest round-trip form, NaN an empty field, lines ending in ``"\n"`` on every system. Columns
    of unequal lengths are refused (pandas' ValueError)."""
    import pandas as pd

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(columns).to_csv(path, index=False, lineterminator="\n")
    return path
