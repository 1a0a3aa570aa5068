"""Writers of results: JSON summaries and CSV tables, readable by any tool."""

from __future__ import annotations

import csv
import io
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
    """Write equal-length columns as a CSV table; floats in their shortest exact (round-trip) form.

    The bytes of ``pandas.DataFrame(columns).to_csv(path, index=False)`` on Linux (lines end in
    ``"\n"`` on every system; NaN is an empty field, infinities ``inf`` and ``-inf``). String names of
    1-D float64 and integer numpy arrays of one length are written without pandas, which a calibration
    otherwise does not load. Anything else goes through pandas: other dtypes (float32 among them),
    masked arrays, Series (aligned on their index), other names (tuples: a header on two rows), and
    columns of unequal lengths (refused).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays = list(columns.values())
    plain = all(isinstance(name, str) for name in columns) and all(
        type(array) is np.ndarray and array.ndim == 1 and (array.dtype == np.float64 or array.dtype.kind in "iu")
        for array in arrays
    )
    if not arrays or not plain or len({array.size for array in arrays}) > 1:  # ragged: pandas' error
        import pandas as pd

        pd.DataFrame(columns).to_csv(path, index=False, lineterminator="\n")
        return path
    header = io.StringIO()
    csv.writer(header, lineterminator="\n").writerow(columns)
    # Python's repr of a float64 is numpy's str of it, which pandas writes: the shortest round-trip form
    cells = [_cells(array) for array in arrays]
    if len(cells) == 1:  # a row of one empty field is quoted, as the csv module writes it: a blank line is no row
        cells[0] = [cell or '""' for cell in cells[0]]
    with open(path, "w", encoding="utf-8", newline="") as file:
        file.write(header.getvalue())
        file.writelines(",".join(row) + "\n" for row in zip(*cells))
    return path


def _cells(array: np.ndarray) -> list[str]:
    """A column's CSV fields: shortest round-trip floats, NaN as an empty field; integers in full."""
    if array.dtype.kind != "f":
        return [str(value) for value in array.tolist()]
    cells = list(map(repr, array.tolist()))
    for row in np.flatnonzero(np.isnan(array)).tolist():
        cells[row] = ""
    return cells
