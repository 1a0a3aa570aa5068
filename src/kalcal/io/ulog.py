"""Read one topic of a PX4 ULog (``.ulg``) into a table, through ``pyulog``.

Each message of the topic is one row; its fields are float64 columns named ``TOPIC.FIELD`` as pyulog
names them (``sensor_combined.accelerometer_m_s2[0]``). A topic logged in several instances is
``TOPIC:N`` (``sensor_accel:1``); ``TOPIC`` alone is instance 0. The ``time`` column is the message's
``timestamp`` (us since the autopilot booted) in float64 s from the log's start (its header's timestamp,
one origin for every topic), except in ``sensor_combined``, whose accelerometer was sampled at
``timestamp + accelerometer_timestamp_relative`` (us): that is its ``time``, since the accelerometer is
what kalcal reads of it (the gyroscope's own time is ``sensor_combined.timestamp``).

Every problem is a :class:`~kalcal.errors.DataError` of one line naming the file and the topic.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from kalcal.errors import DataError

if TYPE_CHECKING:
    import pandas as pd

#: the topic of the accelerometer (and gyroscope) samples the estimator uses
IMU_TOPIC = "sensor_combined"
#: its accelerometer's three axes (m/s^2)
IMU_FIELDS = tuple(f"accelerometer_m_s2[{i}]" for i in range(3))
#: PX4's marker of a relative timestamp that is not valid (INT32_MAX)
RELATIVE_INVALID = 2**31 - 1


def _open(path: Path):
    """The parsed ULog; a DataError naming the file for one pyulog cannot read, finds corrupt (it says so
    on stdout, captured here so that the one line on stderr is all that is said) or that ends before its
    first data message (cut off in its definitions)."""
    import contextlib
    import io

    from pyulog import ULog

    if not path.is_file():
        raise DataError(f"{path}: no such file")
    said = io.StringIO()
    try:
        with contextlib.redirect_stdout(said):
            ulog = ULog(str(path))
    except Exception as exc:  # pyulog raises bare exceptions, struct and OS errors on a damaged file
        text = str(exc).strip() or said.getvalue().strip()
        raise DataError(f"{path}: cannot be read as a ULog: truncated or corrupt "
                        f"({text.splitlines()[0] if text else type(exc).__name__})") from None
    if ulog.file_corruption or not ulog.data_list:
        text = said.getvalue().strip()
        why = text.splitlines()[0] if ulog.file_corruption and text else "no data message after its definitions"
        raise DataError(f"{path}: cannot be read as a ULog: truncated or corrupt ({why})")
    return ulog


def ulog_topics(path: str | Path) -> dict[str, int]:
    """The topics of a ULog, ``{TOPIC or TOPIC:N: message count}``."""
    ulog = _open(Path(path))
    return {_name(d): len(d.data["timestamp"]) for d in sorted(ulog.data_list, key=_name)}


def _name(data) -> str:
    return data.name if data.multi_id == 0 else f"{data.name}:{data.multi_id}"


def read_ulog(path: str | Path, topic: str) -> pd.DataFrame:
    """One topic of a ULog as a DataFrame: ``time`` [s] and ``TOPIC.FIELD`` float64 columns.

    Returns
    -------
    pandas.DataFrame, shape (messages, 1 + fields)
        ``attrs["source"]`` names the file and the topic, ``attrs["time"]`` what the time is,
        ``attrs["time_origin_ns"]`` the log's start [int ns on the autopilot's boot clock],
        ``attrs["time_unit_ns"]`` 1000 (the times are whole us), ``attrs["time_clock"]`` ``"px4"``.
    """
    import pandas as pd

    path = Path(path)
    ulog = _open(path)
    found = {_name(d): d for d in ulog.data_list}
    if topic not in found:
        listing = ", ".join(f"{name} ({len(d.data['timestamp'])} messages)" for name, d in sorted(found.items()))
        raise DataError(f"{path}: no topic {topic} (topics: {listing or 'none'})")
    data = found[topic].data
    stamps = np.asarray(data["timestamp"], dtype=np.int64)
    if stamps.size == 0:
        raise DataError(f"{path}: topic {topic} has no messages")
    what = "timestamp, s from the log's start"
    if found[topic].name == IMU_TOPIC and "accelerometer_timestamp_relative" in data:
        relative = np.asarray(data["accelerometer_timestamp_relative"], dtype=np.int64)
        invalid = np.flatnonzero(relative == RELATIVE_INVALID)
        if invalid.size:
            raise DataError(
                f"{path} topic {topic}: row {invalid[0] + 1}, column 'accelerometer_timestamp_relative': "
                "marked invalid (no accelerometer sample in this message)"
            )
        stamps = stamps + relative
        what = "timestamp + accelerometer_timestamp_relative, s from the log's start"
    # The difference in integer us first, then s: exact for any log shorter than 285 years.
    time = (stamps - int(ulog.start_timestamp)).astype(float) * 1e-6
    columns = {"time": time}
    columns.update({f"{topic}.{field}": np.asarray(values, dtype=float) for field, values in data.items()})
    frame = pd.DataFrame(columns)
    frame.attrs["source"] = f"{path} topic {topic}"
    frame.attrs["time"] = what
    # the origin on the autopilot's boot clock (us, whole): kalcal.io.logs.align_origins
    frame.attrs["time_origin_ns"] = int(ulog.start_timestamp) * 1000
    frame.attrs["time_unit_ns"] = 1000
    frame.attrs["time_clock"] = "px4"
    return frame
