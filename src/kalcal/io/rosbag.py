"""Read one topic of a ROS 1 bag (``.bag``) or a ROS 2 bag (its folder, ``.db3`` or ``.mcap``) into a table.

The bag is read by ``rosbags`` (pure Python; no ROS install). Each message of the topic is one row; its
numeric fields, flattened, are float64 columns named ``TOPIC.FIELD`` (``/imu.linear_acceleration.x``; a
fixed-length array's elements as ``FIELD[i]``, e.g. ``/imu.orientation_covariance[0]``; text and
variable-length arrays are left out). The ``time`` column is the message's header stamp where it has one
(else the time the bag recorded it), in float64 s from the bag's start (the earliest receive time in the
bag, one origin for every topic, so that two topics read from the same bag share their times); the
difference is taken in integer ns before the conversion, so no precision is lost to an epoch.

Every problem is a :class:`~kalcal.errors.DataError` of one line naming the file and the topic: a file
that cannot be read (truncated, not a bag), a topic the bag does not have (the topics it has are
listed), a topic of another message type than required, a topic without messages.
"""

from __future__ import annotations

import operator
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from kalcal.errors import DataError

if TYPE_CHECKING:
    import pandas as pd

#: the message type of an IMU's samples
IMU_TYPE = "sensor_msgs/msg/Imu"
def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


class _Bag:
    """An open bag: its topics and messages, every failure of rosbags a DataError naming the file."""

    def __init__(self, path: Path):
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore

        self.path = path
        kind = "a ROS 1 bag" if path.suffix.lower() == ".bag" else "a ROS 2 bag"
        self.kind = kind
        try:
            # Bags written without their message definitions (older ROS 2) are read with the standard types.
            self.reader = AnyReader([path], default_typestore=get_typestore(Stores.LATEST))
            self.reader.open()
        except Exception as exc:  # rosbags raises its own errors, struct and OS errors on a damaged file
            raise DataError(f"{path}: cannot be read as {kind} ({_first_line(exc)})") from None

    def close(self) -> None:
        try:
            self.reader.close()
        except Exception:  # a reader that failed half-way may not close cleanly; the error is already raised
            pass

    def topics(self) -> dict[str, tuple[str, int]]:
        """``{topic: (message type, message count)}``."""
        return {name: (str(info.msgtype), int(info.msgcount)) for name, info in sorted(self.reader.topics.items())}

    def listing(self) -> str:
        topics = self.topics()
        return ", ".join(f"{name} ({kind}, {count} messages)" for name, (kind, count) in topics.items()) or "none"

    def messages(self, topic: str):
        connections = [c for c in self.reader.connections if c.topic == topic]
        try:
            for connection, stamp, raw in self.reader.messages(connections=connections):
                yield stamp, self.reader.deserialize(raw, connection.msgtype)
        except DataError:
            raise
        except Exception as exc:
            raise DataError(f"{self.path}: topic {topic}: cannot be read as {self.kind} ({_first_line(exc)})") from None


def bag_topics(path: str | Path) -> dict[str, tuple[str, int]]:
    """The topics of a bag, ``{topic: (message type, message count)}``."""
    bag = _Bag(Path(path))
    try:
        return bag.topics()
    finally:
        bag.close()


def _leaves(message: Any) -> list[tuple[str, Callable[[Any], Any], int | None]]:
    """The numeric leaves of a message: ``(name, getter, length)``, length None for a scalar and the
    element count of a fixed-length numeric array."""
    leaves: list[tuple[str, Callable[[Any], Any], int | None]] = []
    for name in getattr(message, "__dataclass_fields__", {}):
        if name.startswith("__"):
            continue
        value = getattr(message, name)
        if hasattr(value, "__dataclass_fields__"):
            leaves += [(f"{name}.{sub}", (lambda get, outer=name: lambda m: get(getattr(m, outer)))(get), n)
                       for sub, get, n in _leaves(value)]
        elif isinstance(value, (bool, int, float, np.integer, np.floating)):
            leaves.append((name, operator.attrgetter(name), None))
        elif isinstance(value, np.ndarray) and value.ndim == 1 and value.dtype.kind in "biuf":
            leaves.append((name, operator.attrgetter(name), int(value.size)))
    return leaves


def _stamp_ns(message: Any) -> int | None:
    """The header stamp in integer ns, None for a message without a header."""
    header = getattr(message, "header", None)
    stamp = getattr(header, "stamp", None)
    if stamp is None:
        return None
    return int(stamp.sec) * 1_000_000_000 + int(getattr(stamp, "nanosec", getattr(stamp, "nsec", 0)))


def read_bag(path: str | Path, topic: str, *, message_type: str | None = None) -> pd.DataFrame:
    """One topic of a bag as a DataFrame: ``time`` [s] and ``TOPIC.FIELD`` float64 columns.

    Parameters
    ----------
    path : path
        A ROS 1 ``.bag``, or a ROS 2 bag's folder, ``.db3`` or ``.mcap`` file.
    topic : str
        The topic, e.g. ``/imu``.
    message_type : str, optional
        The type the topic must have (e.g. ``sensor_msgs/msg/Imu``).

    Returns
    -------
    pandas.DataFrame, shape (messages, 1 + fields)
        ``time``: the header stamp (else the receive time) in s from the bag's start; ``attrs["source"]``
        names the file and the topic, ``attrs["time"]`` what the time is.
    """
    import pandas as pd

    path = Path(path)
    if not path.exists():
        raise DataError(f"{path}: no such file")
    bag = _Bag(path)
    try:
        topics = bag.topics()
        if topic not in topics:
            raise DataError(f"{path}: no topic {topic} (topics: {bag.listing()})")
        kind, count = topics[topic]
        if message_type is not None and kind != message_type:
            raise DataError(f"{path}: topic {topic} holds {kind} messages, expected {message_type}")
        if count == 0:
            raise DataError(f"{path}: topic {topic} has no messages")
        origin = int(bag.reader.start_time)
        stamps: list[int] = []
        rows: list[list[float]] = []
        leaves = None
        header = True
        for received, message in bag.messages(topic):
            if leaves is None:
                leaves = _leaves(message)
                header = _stamp_ns(message) is not None
            stamps.append(_stamp_ns(message) if header else int(received))
            row: list[float] = []
            for _, get, size in leaves:
                value = get(message)
                if size is None:
                    row.append(float(value))
                else:
                    value = np.asarray(value, dtype=float).ravel()
                    row.extend(value[:size] if value.size >= size else np.concatenate([value, np.full(size - value.size, np.nan)]))
            rows.append(row)
    finally:
        bag.close()
    if not rows:
        raise DataError(f"{path}: topic {topic} has no messages")
    names = [f"{topic}.{name}" if size is None else f"{topic}.{name}[{i}]"
             for name, _, size in leaves for i in (range(size) if size is not None else [0])]
    # The difference in integer ns first: a float64 epoch in ns would round to 256 ns.
    time = (np.asarray(stamps, dtype=np.int64) - origin).astype(float) * 1e-9
    frame = pd.DataFrame(np.asarray(rows, dtype=float).reshape(len(rows), len(names)), columns=names)
    frame.insert(0, "time", time)
    frame.attrs["source"] = f"{path} topic {topic}"
    frame.attrs["type"] = kind
    frame.attrs["time"] = (
        "header stamp, s from the bag's start" if header else "receive time (no header), s from the bag's start"
    )
    return frame


def imu_topic(path: str | Path) -> str:
    """The bag's only ``sensor_msgs/msg/Imu`` topic; a DataError listing the topics when it has none or several."""
    path = Path(path)
    if not path.exists():
        raise DataError(f"{path}: no such file")
    bag = _Bag(path)
    try:
        topics = bag.topics()
        imu = [name for name, (kind, _) in topics.items() if kind == IMU_TYPE]
        if len(imu) != 1:
            which = "no" if not imu else "several"
            raise DataError(f"{path}: {which} {IMU_TYPE} topics: name one with --topic (topics: {bag.listing()})")
        return imu[0]
    finally:
        bag.close()
