"""Read sensor logs (CSV, also compressed, Parquet, ROS bags, PX4 ULog, or a DataFrame) into validated float columns.

The reader is chosen by the file's name (:data:`READERS`, :func:`log_format`).
Every problem raises :class:`~kalcal.errors.DataError` naming the file, the column and, where there is
one, the row (1-based, counting data rows after the header, or messages of a topic) and the value. CSV
and Parquet are read by pandas (``read_csv``, which decompresses ``.csv.gz``, ``.csv.bz2``, ``.csv.xz``
and, with the ``zstandard`` package installed, ``.csv.zst``; ``read_parquet``). A ROS 1 or ROS 2 bag
(:mod:`kalcal.io.rosbag`) or a ULog (:mod:`kalcal.io.ulog`) holds topics: one read is one topic, a table
of ``time`` [s] and ``TOPIC.FIELD`` columns (``/imu.linear_acceleration.x``,
``sensor_combined.accelerometer_m_s2[0]``), named in every message as ``FILE topic TOPIC``. The topic is
given, or read off the columns asked for (the part of ``TOPIC.FIELD`` before its first dot).
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

#: the format of a log by its name's ending (a ROS 2 bag may also be its folder, :func:`log_format`)
READERS = {
    ".csv": "csv",
    ".csv.gz": "csv",
    ".csv.bz2": "csv",
    ".csv.xz": "csv",
    ".csv.zst": "csv",
    ".parquet": "parquet",
    ".pq": "parquet",
    ".bag": "rosbag",
    ".db3": "rosbag",
    ".mcap": "rosbag",
    ".ulg": "ulog",
}
#: formats that hold topics, each read as a table of its own
TOPIC_FORMATS = ("rosbag", "ulog")
#: what the formats are called in messages
FORMAT_NAMES = "CSV (.csv, .csv.gz, .csv.bz2, .csv.xz, .csv.zst), Parquet, ROS bag (.bag, .db3, .mcap, bag folder), ULog (.ulg)"


def log_format(path: str | Path) -> str | None:
    """``"csv"``, ``"parquet"``, ``"rosbag"`` or ``"ulog"`` by the name's ending (a folder holding a
    ROS 2 bag's ``metadata.yaml`` is ``"rosbag"``); None when unknown."""
    path = Path(path)
    name = path.name.lower()
    for ending in sorted(READERS, key=len, reverse=True):
        if name.endswith(ending):
            return READERS[ending]
    if path.is_dir() and (path / "metadata.yaml").is_file():
        return "rosbag"
    return None


def topic_of(columns: Mapping[str, str] | Sequence[str], path: str | Path = "") -> str | None:
    """The one topic that ``TOPIC.FIELD`` column names name (None when none names one); a DataError when
    they name several (one read of a bag or ULog is one topic)."""
    names = columns.values() if isinstance(columns, Mapping) else columns
    topics = sorted({name.split(".", 1)[0] for name in names if "." in name and name.split(".", 1)[0]})
    if len(topics) > 1:
        raise DataError(f"{path}: columns name topics {', '.join(topics)}: one log is read from one topic")
    return topics[0] if topics else None


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


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _compression(path: Path) -> str | None:
    """``".gz"``, ``".bz2"``, ``".xz"`` or ``".zst"`` for a compressed log, None for another."""
    suffix = path.suffix.lower()
    return suffix if suffix in (".gz", ".bz2", ".xz", ".zst") else None


def _decompression_errors() -> tuple[type[BaseException], ...]:
    """What a damaged compressed file raises while read: a truncated stream's EOFError (gzip, bz2, lzma),
    OSError (gzip.BadGzipFile, bz2's "Invalid data stream"), zlib.error, lzma.LZMAError and, with the
    package, zstandard.ZstdError."""
    import lzma
    import zlib

    errors: tuple[type[BaseException], ...] = (EOFError, OSError, zlib.error, lzma.LZMAError)
    zstandard = sys.modules.get("zstandard")
    return errors + ((zstandard.ZstdError,) if zstandard is not None else ())


def _check_compressed(path: Path, compressed: str) -> None:
    """Decompress a file to its end, the output discarded (memory: one chunk): raises what the damaged
    stream raises (:func:`_decompression_errors`), EOFError for a ``.zst`` whose last frame is cut short."""
    if compressed != ".zst":
        import bz2
        import gzip
        import lzma

        opener = {".gz": gzip.open, ".bz2": bz2.open, ".xz": lzma.open}[compressed]
        with opener(path, "rb") as stream:
            while stream.read(1 << 20):
                pass
        return
    import zstandard

    with open(path, "rb") as handle:
        decompressor = zstandard.ZstdDecompressor().decompressobj()
        pending = handle.read(1 << 20)
        if not pending:
            return  # an empty file: pandas says so
        while True:
            chunk = pending or handle.read(1 << 20)
            pending = b""
            if not chunk:
                break
            decompressor.decompress(chunk)
            if decompressor.eof:  # a frame ended: the rest (unused_data) starts the next frame
                pending = decompressor.unused_data
                decompressor = zstandard.ZstdDecompressor().decompressobj()
                if not pending:
                    pending = handle.read(1 << 20)
                    if not pending:
                        return
        if not decompressor.eof:
            raise EOFError("the compressed stream ends before its last frame does")


def source_name(source: str | Path | pd.DataFrame, role: str, frame: pd.DataFrame | None = None) -> str:
    """How messages name a log: its path, ``FILE topic TOPIC`` for a topic read from a bag or ULog (given
    its ``frame`` from :func:`read_table`), or ``<ROLE DataFrame>`` for a DataFrame (``<imu DataFrame>``)."""
    if frame is not None and "source" in frame.attrs:
        return str(frame.attrs["source"])
    return f"<{role} DataFrame>" if is_frame(source) else str(source)


def read_table(
    path: str | Path | pd.DataFrame,
    role: str = "log",
    *,
    topic: str | None = None,
    columns: Mapping[str, str] | Sequence[str] = (),
    topic_hint: str = "",
) -> pd.DataFrame:
    """Read a log; refuse missing, unreadable or empty files.

    Parameters
    ----------
    path : path or DataFrame
        The log (:func:`log_format` picks the reader).
    role : str
        What the log is (``imu``, ``gps``, ``data``): names a DataFrame in messages.
    topic : str, optional
        For a bag or ULog: the topic to read (default: the one ``columns`` name). Refused for other logs.
    columns : mapping or sequence
        The columns the caller will take (``{role: column}`` or names): a bag's or ULog's topic is read off
        their ``TOPIC.FIELD`` names when ``topic`` is not given.
    topic_hint : str
        For a bag or ULog read with no topic named: what the caller takes of a topic, said after the topics
        (a scenario's own words, such as which message types its GPS log may be).

    Returns a DataFrame, its column names stripped; a topic's has ``attrs["source"]`` (``FILE topic
    TOPIC``, :func:`source_name`). A DataFrame is taken as the file's content (a copy, with the same
    checks): empty is refused under the name ``<ROLE DataFrame>`` (:func:`source_name`).
    """
    if is_frame(path):
        if topic is not None:
            raise DataError(f"{source_name(path, role)}: --topic applies to a ROS bag or a ULog, not a DataFrame")
        if path.shape[0] == 0:
            raise DataError(f"{source_name(path, role)}: has columns but no data rows")
        frame = path.copy()
        frame.columns = [str(c).strip() for c in frame.columns]
        return frame.reset_index(drop=True)
    path = Path(path)
    kind = log_format(path)
    if kind is None:
        ending = "".join(path.suffixes[-2:]) if path.suffix.lower() in (".gz", ".bz2", ".xz", ".zst") else path.suffix
        raise DataError(f"{path}: unknown file type {ending!r} (expected {FORMAT_NAMES})")
    if kind in TOPIC_FORMATS:
        return _read_topic(path, kind, topic or topic_of(columns, path), topic_hint)
    if topic is not None:
        raise DataError(f"{path}: --topic {topic}: applies to a ROS bag or a ULog, not a {kind} file")
    if not path.is_file():
        raise DataError(f"{path}: no such file")
    compressed = _compression(path)
    if compressed == ".zst":
        try:
            import zstandard  # noqa: F401  (pandas' reader of .zst)
        except ImportError:
            raise DataError(f"{path}: reading a .zst file needs the zstandard package (pip install zstandard)") from None
    try:
        if compressed is not None:
            # the whole stream first: pandas would parse a damaged stream's garbage (a CSV error, not the
            # cause) before the checksum at its end, and reads a truncated .zst's first blocks as the whole
            _check_compressed(path, compressed)
        frame = _read_parquet(path) if kind == "parquet" else _read_csv(path)
    except _EmptyFile:
        raise DataError(f"{path}: file is empty") from None
    except _decompression_errors() as exc:
        if compressed is None:
            raise DataError(f"{path}: cannot be read as {kind} ({_first_line(exc)})") from None
        raise DataError(f"{path}: cannot be read as {compressed} compressed CSV: corrupt or truncated "
                        f"({_first_line(exc)})") from None
    except (UnicodeDecodeError, ValueError) as exc:  # pandas' ParserError and pyarrow's ArrowInvalid too
        raise DataError(f"{path}: cannot be read as {kind} ({_first_line(exc)})") from None
    if len(frame) == 0:
        raise DataError(f"{path}: has a header but no data rows")
    frame.columns = [str(c).strip() for c in frame.columns]
    return frame


def _read_topic(path: Path, kind: str, topic: str | None, topic_hint: str = "") -> pd.DataFrame:
    """One topic of a bag or ULog (:mod:`kalcal.io.rosbag`, :mod:`kalcal.io.ulog`); ``topic_hint`` ends the
    message that asks for a topic (what the caller takes of one)."""
    if not path.exists():
        raise DataError(f"{path}: no such file")
    what = "a ROS bag" if kind == "rosbag" else "a ULog"
    if topic is None:
        if kind == "rosbag":
            from kalcal.io.rosbag import bag_topics

            listing = ", ".join(f"{name} ({msgtype})" for name, (msgtype, _) in bag_topics(path).items())
        else:
            from kalcal.io.ulog import ulog_topics

            listing = ", ".join(f"{name} ({count} messages)" for name, count in ulog_topics(path).items())
        raise DataError(
            f"{path}: {what} holds topics: name the columns as TOPIC.FIELD "
            f"(e.g. /imu.linear_acceleration.x, sensor_combined.accelerometer_m_s2[0]) or give the topic (topics: {listing})"
            + (f"; {topic_hint}" if topic_hint else "")
        )
    if kind == "rosbag":
        from kalcal.io.rosbag import read_bag

        return read_bag(path, topic)
    from kalcal.io.ulog import read_ulog

    return read_ulog(path, topic)


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


#: the float64 seconds of one time unit, as the readers convert whole units (ns for bags, us for ULog)
_UNIT_SECONDS = {1: 1e-9, 1000: 1e-6}


def align_origins(logs: Sequence[tuple[str, np.ndarray, Mapping[str, Any]]]) -> list[np.ndarray]:
    """The times of logs used together, put on one origin: the earliest of theirs, exactly.

    Parameters
    ----------
    logs : sequence of (name, time, attrs)
        Each log's name in messages, its ``time`` column [s], shape (n,), and its table's ``attrs``: a
        topic of a bag or ULog has ``time_origin_ns`` (its t = 0 in integer ns on ``time_clock``) and
        ``time_unit_ns`` (its times are whole units from it); a CSV, Parquet or DataFrame has none, its
        times being relative to nothing kalcal can know.

    Returns
    -------
    list of numpy.ndarray
        The times [s], each from the earliest origin: a log at a later origin has its whole units from its
        own origin plus the difference of the origins, converted as its reader converts them, so that it
        is bit for bit what reading it from the earlier origin gives. Logs without origins are returned
        as they are (their times are taken to share one axis, as before).

    Raises
    ------
    DataError
        One line, where one log has an absolute origin and another none (a bag's or ULog's topic with a
        CSV: the two cannot be aligned), or where the origins are on different clocks (a ROS bag's stamps
        and a ULog's boot clock).
    """
    times = [np.asarray(time, dtype=float) for _, time, _ in logs]
    origins = [attrs.get("time_origin_ns") for _, _, attrs in logs]
    if all(origin is None for origin in origins):
        return times
    if any(origin is None for origin in origins):
        with_origin = next(name for (name, _, _), o in zip(logs, origins) if o is not None)
        without = next(name for (name, _, _), o in zip(logs, origins) if o is None)
        raise DataError(
            f"{without}: its times have no absolute origin, while {with_origin}'s are from a recorded stamp: the two "
            "logs cannot be aligned (give both as topics of bags or ULogs, or both as tables on one time axis)")
    clocks = {attrs.get("time_clock") for _, _, attrs in logs}
    if len(clocks) > 1:
        raise DataError(
            f"{logs[0][0]} and {logs[1][0]}: their times are on different clocks ({' and '.join(sorted(map(str, clocks)))} "
            "stamps): the two logs cannot be aligned")
    common = min(int(origin) for origin in origins)
    aligned = []
    for (name, _, attrs), time, origin in zip(logs, times, origins):
        if int(origin) == common:
            aligned.append(time)
            continue
        unit = int(attrs.get("time_unit_ns", 1))
        scale = _UNIT_SECONDS.get(unit, unit * 1e-9)
        units = np.rint(time / scale).astype(np.int64)
        shift = (int(origin) - common) // unit
        if (int(origin) - common) % unit == 0 and np.array_equal(units.astype(float) * scale, time):
            aligned.append((units + shift).astype(float) * scale)  # as the reader would have converted them
        else:  # times changed since they were read: the float difference of the origins
            aligned.append(time + (int(origin) - common) * 1e-9)
    return aligned
