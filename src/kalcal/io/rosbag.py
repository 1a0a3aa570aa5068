"""Read one topic of a ROS 1 bag (``.bag``) or a ROS 2 bag (its folder, ``.db3`` or ``.mcap``) into a table.

The bag is read by ``rosbags`` (pure Python; no ROS install). Each message of the topic is one row; its
numeric fields, flattened, are float64 columns named ``TOPIC.FIELD`` (``/imu.linear_acceleration.x``; a
fixed-length array's elements as ``FIELD[i]``, e.g. ``/imu.orientation_covariance[0]``). Text, arrays of
messages and variable-length arrays (sequences, such as a ``Float64MultiArray``'s ``data``) are left out,
as the message definition says which a field is: a column of a sequence would change its length from
message to message. The ``time`` column is the message's header stamp where it has one (else the time
the bag recorded it) in float64 s from the topic's first message's; the difference is taken in integer
ns before the conversion, so no precision is lost to an epoch (header stamps on a boot or simulation
clock recorded on the wall clock included). That origin, in integer ns on the stamps' clock, is
``attrs["time_origin_ns"]``: where two topics are used together (accel-gps' ``--imu`` and ``--gps``) both
are put on the earlier one (:func:`kalcal.io.logs.align_origins`), exactly.

The values are collected into one preallocated float64 array of (messages, fields) (the bag's index gives
the message count): memory is the columns' own size plus a constant, not a Python object per value.

Every problem is a :class:`~kalcal.errors.DataError` of one line naming the file and the topic: a file
that cannot be read (truncated, not a bag), a topic the bag does not have (the topics it has are
listed), a topic of another message type than required, a topic without messages.
"""

from __future__ import annotations

import keyword
from collections.abc import Callable, Mapping
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


#: the base types of ROS messages that are numbers (read as float64)
NUMERIC_BASES = frozenset({
    "bool", "byte", "char", "octet", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64",
    "float32", "float64",
})


def _leaves(fielddefs: Mapping[str, Any], msgtype: str, prefix: str = "") -> list[tuple[str, int | None]]:
    """The numeric leaves of a message type, from its definition: ``(dotted name, length)``, length None
    for a scalar and the element count of a fixed-length numeric array. Sequences (variable-length
    arrays), text and arrays of messages are left out."""
    from rosbags.typesys.store import Nodetype

    leaves: list[tuple[str, int | None]] = []
    for field, (node, detail) in fielddefs[msgtype][1]:
        # the attribute rosbags gives the field (a Python keyword gets a trailing "_", as rosbags' codegen does)
        name = f"{field}_" if keyword.iskeyword(field) else field
        if not name.isidentifier():
            continue  # not an attribute of the message (rosbags' parser admits none such)
        if node == Nodetype.NAME:
            leaves += _leaves(fielddefs, detail, f"{prefix}{name}.")
        elif node == Nodetype.BASE and detail[0] in NUMERIC_BASES:
            leaves.append((f"{prefix}{name}", None))
        elif node == Nodetype.ARRAY and detail[0][0] == Nodetype.BASE and detail[0][1][0] in NUMERIC_BASES:
            leaves.append((f"{prefix}{name}", int(detail[1])))
    return leaves


def _row_getter(leaves: list[tuple[str, int | None]]) -> Callable[[Any], tuple]:
    """One function of a message giving its numeric leaves as one flat tuple, in the order of ``leaves``
    (generated once per topic: an attribute path per leaf, no Python loop per field and message). Every
    part of every path is a Python identifier (:func:`_leaves` keeps no other), so the generated source is
    attribute access only."""
    items = ", ".join(f"m.{name}" if size is None else f"*m.{name}" for name, size in leaves)
    return eval(f"lambda m: ({items}{',' if len(leaves) == 1 else ''})")  # noqa: S307  (names from the typestore)


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
        ``time``: the header stamp (else the receive time) in s from the topic's first message's;
        ``attrs["source"]`` names the file and the topic, ``attrs["time"]`` what the time is,
        ``attrs["time_origin_ns"]`` the first message's stamp [int ns], ``attrs["time_unit_ns"]`` 1 (the
        times are whole ns) and ``attrs["time_clock"]`` ``"ros"`` (:func:`kalcal.io.logs.align_origins`).
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
        leaves = _leaves(bag.reader.typestore.fielddefs, kind)
        width = sum(1 if size is None else size for _, size in leaves)
        row_of = _row_getter(leaves) if leaves else (lambda m: ())
        # preallocated from the index's count: the values go straight into float64, no Python float each
        values = np.empty((count, width), dtype=float)
        stamps = np.empty(count, dtype=np.int64)
        header = True
        n = 0
        for received, message in bag.messages(topic):
            if n == 0:
                header = _stamp_ns(message) is not None
            if n == count:  # more messages than the index said: grow (a bag being written while read)
                values = np.concatenate([values, np.empty_like(values)])
                stamps = np.concatenate([stamps, np.empty_like(stamps)])
                count *= 2
            stamps[n] = _stamp_ns(message) if header else int(received)
            try:
                values[n] = row_of(message)
            except (TypeError, ValueError) as exc:  # a fixed-length array of another length
                raise DataError(f"{path} topic {topic}: message {n + 1}: {_first_line(exc)}") from None
            n += 1
    finally:
        bag.close()
    if n == 0:
        raise DataError(f"{path}: topic {topic} has no messages")
    values, stamps = values[:n], stamps[:n]
    names = [f"{topic}.{name}" if size is None else f"{topic}.{name}[{i}]"
             for name, size in leaves for i in (range(size) if size is not None else [0])]
    # The origin is the first message's stamp, on the stamps' own clock; the difference in integer ns
    # first, since a float64 epoch in ns would round to 256 ns.
    origin = int(stamps[0])
    time = (stamps - origin).astype(float) * 1e-9
    frame = pd.DataFrame(values, columns=names, copy=False)
    frame.insert(0, "time", time)
    frame.attrs["source"] = f"{path} topic {topic}"
    frame.attrs["type"] = kind
    frame.attrs["time"] = (
        "header stamp, s from the topic's first message's" if header
        else "receive time (no header), s from the topic's first message's"
    )
    frame.attrs["time_origin_ns"] = origin
    frame.attrs["time_unit_ns"] = 1
    frame.attrs["time_clock"] = "ros"
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
