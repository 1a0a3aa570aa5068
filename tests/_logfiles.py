"""Bags written for the tests with rosbags' own writers: ROS 1 (.bag) and ROS 2 (sqlite3 or mcap), each
holding known samples."""

from __future__ import annotations

from pathlib import Path

import numpy as np

ORIGIN_NS = 1_700_000_000_000_000_000  #: the first message's receive time and header stamp, ns since the epoch


def _typestore(ros: int):
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS1_NOETIC if ros == 1 else Stores.ROS2_HUMBLE)


def _imu(ts, stamp_ns: int, accel, seq: int):
    t = ts.types
    header = {"stamp": t["builtin_interfaces/msg/Time"](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9), "frame_id": "imu"}
    if "seq" in t["std_msgs/msg/Header"].__dataclass_fields__:
        header["seq"] = seq
    vector, zeros = t["geometry_msgs/msg/Vector3"], np.zeros(9)
    return t["sensor_msgs/msg/Imu"](
        header=t["std_msgs/msg/Header"](**header),
        orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0), orientation_covariance=zeros,
        angular_velocity=vector(x=0.0, y=0.0, z=0.0), angular_velocity_covariance=zeros,
        linear_acceleration=vector(x=float(accel[0]), y=float(accel[1]), z=float(accel[2])),
        linear_acceleration_covariance=zeros,
    )


def write_imu_bag(path, stamps_ns, accel, *, ros: int = 1, topic: str = "/imu", storage: str = "sqlite3",
                  extra: dict | None = None, receive_ns=None) -> Path:
    """A bag with ``accel`` (n, 3) m/s^2 as sensor_msgs/Imu on ``topic``, header stamps ``stamps_ns`` (int
    ns); ``extra`` maps more topics to ``(msgtype, [message, ...])`` of std types, received 1 ms apart
    from the first stamp, or to ``(msgtype, [message, ...], receive_ns)``.
    ``receive_ns`` are the recorded (receive) times, default the stamps. A ROS 2 bag is its folder."""
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin, Writer as Writer2

    path = Path(path)
    ts = _typestore(ros)
    serialize = ts.serialize_ros1 if ros == 1 else ts.serialize_cdr
    receive = stamps_ns if receive_ns is None else receive_ns
    if ros == 1:
        writer = Writer1(path)
    else:
        plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
        writer = Writer2(path, version=9, storage_plugin=plugin)
    with writer:
        connection = writer.add_connection(topic, "sensor_msgs/msg/Imu", typestore=ts)
        for i, (stamp, received, row) in enumerate(zip(stamps_ns, receive, np.asarray(accel, dtype=float))):
            writer.write(connection, int(received), serialize(_imu(ts, int(stamp), row, i), connection.msgtype))
        for name, (msgtype, messages, *times) in (extra or {}).items():
            other = writer.add_connection(name, msgtype, typestore=ts)
            times = times[0] if times else [int(stamps_ns[0]) + i * 1_000_000 for i in range(len(messages))]
            for time, message in zip(times, messages):
                writer.write(other, int(time), serialize(message, msgtype))
    return path


def float64_messages(ros: int, values):
    """std_msgs/Float64 messages (no header) of ``values``."""
    ts = _typestore(ros)
    return [ts.types["std_msgs/msg/Float64"](data=float(v)) for v in values]


def odometry_messages(ros: int, stamps_ns, position, velocity):
    """nav_msgs/Odometry messages: ``position`` [m] as pose.pose.position.x, ``velocity`` [m/s] as
    twist.twist.linear.x, header stamps ``stamps_ns``."""
    t = _typestore(ros).types
    header = t["std_msgs/msg/Header"]
    extra = {"seq": 0} if "seq" in header.__dataclass_fields__ else {}
    point, vector, zeros = t["geometry_msgs/msg/Point"], t["geometry_msgs/msg/Vector3"], np.zeros(36)
    return [
        t["nav_msgs/msg/Odometry"](
            header=header(**extra, stamp=t["builtin_interfaces/msg/Time"](sec=int(s) // 10**9, nanosec=int(s) % 10**9), frame_id="map"),
            child_frame_id="base",
            pose=t["geometry_msgs/msg/PoseWithCovariance"](
                pose=t["geometry_msgs/msg/Pose"](position=point(x=float(p), y=0.0, z=0.0),
                                                  orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)),
                covariance=zeros),
            twist=t["geometry_msgs/msg/TwistWithCovariance"](
                twist=t["geometry_msgs/msg/Twist"](linear=vector(x=float(v), y=0.0, z=0.0), angular=vector(x=0.0, y=0.0, z=0.0)),
                covariance=zeros),
        )
        for s, p, v in zip(stamps_ns, position, velocity)
    ]
