"""Read sensor logs (CSV or Parquet, chosen by extension, or a pandas DataFrame) into validated float columns.

Every problem raises :class:`~kalcal.errors.DataError` naming the file, the column and, where there is
one, the row (1-based, counting data rows after the header) and the value. Both formats are read by
pandas (``read_csv``, ``read_parquet``).
"""

from __future__ import annotations

import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from kalcal.errors import DataError

if TYPE_CHECKING:
    import pandas as pd

READERS = {".csv": "csv", ".parquet": "parquet", ".pq": "parquet"}


def is_frame(value: Any) -> bool:
    """Whether ``value`` is a pandas DataFrame, without importing pandas (none can exist before it is)."""
    pandas = sys.modules.get("pandas")
    return pandas is not None and isinstance(value, pandas.DataFrame)


def _read_parquet(path: Path) -> pd.DataFrame:
    import pandas as pd

    return pd.read_parquet(path)


class _EmptyFile(Exception):
    """A CSV file with nothing in it (pandas' EmptyDataError, which is a ValueError)."""


def _read_csv(path: Path) -> pd.DataFrame:
    import pandas as pd

    try:
        return pd.read_csv(path, skipinitialspace=True)
    except pd.errors.EmptyDataError:
        raise _EmptyFile from None


def source_name(source: str | Path | pd.DataFrame, role: str) -> str:
    """How messages name a log: its path, or ``<ROLE DataFrame>`` for a DataFrame (``<imu DataFrame>``)."""
    return f"<{role} DataFrame>" if is_frame(source) else str(source)


def read_table(path: str | Path | pd.DataFrame, role: str = "log") -> pd.DataFrame:
    """Read a CSV or Parquet file; refuse missing, unreadable or empty files.

    Returns a DataFrame, its column names stripped. A DataFrame is taken as the file's content (a copy, with the same checks): empty is refused under the name
    ``<ROLE DataFrame>`` (:func:`source_name`).
    """
    if is_frame(path):
        if path.shape[0] == 0:
            raise DataError(f"{source_name(path, role)}: has columns but no data rows")
        frame = path.copy()
        frame.columns = [str(c).strip() for c in frame.columns]
        return frame.reset_index(drop=True)
    path = Path(path)
    kind = READERS.get(path.suffix.lower())
    if kind is None:
        raise DataError(f"{path}: unknown file type {path.suffix!r} (expected .csv or .parquet)")
    if not path.is_file():
        raise DataError(f"{path}: no such file")
    try:
        frame = _read_parquet(path) if kind == "parquet" else _read_csv(path)
    except _EmptyFile:
        raise DataError(f"{path}: file is empty") from None
    except (UnicodeDecodeError, OSError, ValueError) as exc:  # pandas' ParserError and pyarrow's ArrowInvalid too
        first_line = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise DataError(f"{path}: cannot be read as {kind} ({first_line})") from None
    if len(frame) == 0:
        raise DataError(f"{path}: has a header but no data rows")
    frame.columns = [str(c).strip() for c in frame.columns]
    return frame


def numeric_columns(
    frame: pd.DataFrame,
    path: str | Path,
    columns: Mapping[str, str] | Sequence[str],
    *,
    allow_nan: Sequence[str] = (),
) -> dict[str, np.ndarray]:
    """Extract columns as float arrays.

    Parameters
    ----------
    columns : mapping or sequence
        ``{role: column name in the file}`` (or names, each its own role).
    allow_nan : sequence of str
        Roles whose empty or NaN cells are kept as NaN; elsewhere they are errors. Infinite values are
        always errors.
    """
    mapping = dict(columns) if isinstance(columns, Mapping) else {name: name for name in columns}
    result: dict[str, np.ndarray] = {}
    for role, name in mapping.items():
        if name not in frame.columns:
            raise DataError(
                f"{path}: missing column {name!r}" + (f" for {role}" if role != name else "")
                + f" (columns: {', '.join(map(str, frame.columns))})"
            )
        values = _parsed(frame[name], path, name)
        not_finite = ~np.isfinite(values) if role not in allow_nan else np.isinf(values)
        if np.any(not_finite):
            row = int(np.argmax(not_finite))
            raise DataError(f"{path}: row {row + 1}, column {name!r}: value is {float(values[row])!r}, expected a finite number")
        result[role] = values
    return result


def _parsed(raw: pd.Series, path: str | Path, name: str) -> np.ndarray:
    """A frame's column as floats; a cell that is text is a DataError. Cells that do not parse as numbers
    but are empty or "nan" stay NaN (allowed or not by the caller)."""
    import pandas as pd

    values = pd.to_numeric(raw, errors="coerce").to_numpy(dtype=float)
    unparsed = np.flatnonzero(np.isnan(values))
    if unparsed.size:
        text = raw.iloc[unparsed]
        is_text = text.notna().to_numpy() & (text.astype(str).str.strip().str.lower() != "nan").to_numpy()
        if np.any(is_text):
            row = int(unparsed[np.argmax(is_text)])
            raise DataError(f"{path}: row {row + 1}, column {name!r}: not a number: {raw.iloc[row]!r}")
    return values


def require_increasing(time: np.ndarray, path: str | Path, column: str = "time") -> None:
    """Raise DataError unless ``time`` increases strictly."""
    steps = np.diff(time)
    bad = ~(steps > 0)
    if np.any(bad):
        row = int(np.argmax(bad)) + 1
        raise DataError(
            f"{path}: row {row + 1}, column {column!r}: time {time[row]:.9g} does not increase "
            f"(previous row {time[row - 1]:.9g})"
        )


def parse_column_map(text: str | None, roles: tuple[str, ...], option: str) -> dict[str, str]:
    """``"time=t,accel=ax"`` -> ``{"time": "t", "accel": "ax"}``; roles not named keep their own name.

    Raises DataError for a role that is not one of ``roles`` or a malformed item.
    """
    mapping = {role: role for role in roles}
    for item in filter(None, (part.strip() for part in (text or "").split(","))):
        role, sep, column = item.partition("=")
        role, column = role.strip(), column.strip()
        if not sep or not column:
            raise DataError(f"{option} {text!r}: expected role=column pairs, e.g. time=t,accel=ax")
        if role not in roles:
            raise DataError(f"{option}: unknown role {role!r} (roles: {', '.join(roles)})")
        mapping[role] = column
    return mapping
