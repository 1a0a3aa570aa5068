"""ROS 1/2 bags, PX4 ULog and compressed CSV read as tables: the samples and times as written, every bad
file one DataError line naming the file (and the topic)."""

from __future__ import annotations

import bz2
import gzip
import lzma
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from kalcal.errors import DataError
from kalcal.io.logs import read_table, source_name
from kalcal.io.rosbag import read_bag
from kalcal.io.ulog import read_ulog
from tests._logfiles import ORIGIN_NS, float64_messages, write_imu_bag

ULOG = Path(__file__).resolve().parents[1] / "data" / "px4-ulog" / "sample_log_small.ulg"
AXES = [f"/imu.linear_acceleration.{a}" for a in "xyz"]


def _signal(n: int = 50, seed: int = 3):
    rng = np.random.default_rng(seed)
    stamps = ORIGIN_NS + np.arange(n, dtype=np.int64) * 5_000_000 + rng.integers(0, 1000, n)  # ns, jittered
    return stamps, rng.normal([0.1, -0.2, 9.81], 0.01, (n, 3))


@pytest.mark.parametrize("ros, storage, name", [(1, "", "s.bag"), (2, "sqlite3", "s2"), (2, "mcap", "s2m")])
def test_a_bag_topic_reads_as_written(tmp_path, ros, storage, name):
    """Header stamps (not receive times) in s from the first message's stamp, taken in integer ns; float64
    samples bit for bit; the origin kept as integer ns."""
    stamps, accel = _signal()
    receive = stamps + 3_000_000 + np.arange(stamps.size) * 7  # recorded 3 ms (and more) after the stamp
    bag = write_imu_bag(tmp_path / name, stamps, accel, ros=ros, storage=storage, receive_ns=receive)
    frame = read_table(bag, "imu", columns={"accel": AXES[0]})
    np.testing.assert_array_equal(frame["time"].to_numpy(), (stamps - stamps[0]).astype(float) * 1e-9)
    assert frame.attrs["time_origin_ns"] == int(stamps[0]) and frame.attrs["time_clock"] == "ros"
    np.testing.assert_array_equal(frame[AXES].to_numpy(), accel)
    assert source_name(bag, "imu", frame) == f"{bag} topic /imu"
    assert frame.attrs["time"].startswith("header stamp")
    if ros == 2:  # the storage file itself reads the same as its folder
        storage_file = next(p for p in bag.iterdir() if p.suffix in (".db3", ".mcap"))
        pd.testing.assert_frame_equal(read_bag(storage_file, "/imu")[AXES], frame[AXES])


def test_a_topic_without_header_takes_the_receive_time(tmp_path):
    stamps, accel = _signal(5)
    bag = write_imu_bag(tmp_path / "h.bag", stamps, accel, extra={"/value": ("std_msgs/msg/Float64", float64_messages(1, [1, 2, 3]))})
    frame = read_table(bag, topic="/value")
    np.testing.assert_array_equal(frame["time"], [0.0, 1e-3, 2e-3])
    np.testing.assert_array_equal(frame["/value.data"], [1.0, 2.0, 3.0])
    assert frame.attrs["time"].startswith("receive time")


def _error(call) -> str:
    with pytest.raises(DataError) as info:
        call()
    message = str(info.value)
    assert "\n" not in message
    return message


def test_bad_bags_are_one_line_naming_file_and_topic(tmp_path):
    stamps, accel = _signal()
    bag = write_imu_bag(tmp_path / "b.bag", stamps, accel, extra={"/value": ("std_msgs/msg/Float64", [])})
    assert "no topic /imu/data (topics: /imu (sensor_msgs/msg/Imu, 50 messages), /value (std_msgs/msg/Float64, 0 messages))" in _error(lambda: read_table(bag, topic="/imu/data"))
    assert _error(lambda: read_table(bag, topic="/value")).endswith("topic /value has no messages")
    assert "holds std_msgs/msg/Float64 messages, expected sensor_msgs/msg/Imu" in _error(
        lambda: read_bag(bag, "/value", message_type="sensor_msgs/msg/Imu"))
    assert "name the columns as TOPIC.FIELD" in _error(lambda: read_table(bag, columns={"accel": "accel"}))
    assert "columns name topics /a, /imu" in _error(lambda: read_table(bag, columns={"t": "/imu.x", "a": "/a.y"}))
    truncated = tmp_path / "t.bag"
    truncated.write_bytes(bag.read_bytes()[: bag.stat().st_size // 2])
    assert _error(lambda: read_table(truncated, columns=AXES)).startswith(f"{truncated}: cannot be read as a ROS 1 bag (")
    assert _error(lambda: read_table(tmp_path / "none.bag", columns=AXES)) == f"{tmp_path / 'none.bag'}: no such file"


def test_ulog_reads_as_pyulog_reads_it():
    """sensor_combined: time = timestamp + accelerometer_timestamp_relative (us) from the log's start, in s."""
    from pyulog import ULog

    ulog = ULog(str(ULOG))
    data = ulog.get_dataset("sensor_combined").data
    frame = read_ulog(ULOG, "sensor_combined")
    assert len(frame) == 1298
    expected = (data["timestamp"].astype(np.int64) + data["accelerometer_timestamp_relative"] - ulog.start_timestamp) * 1e-6
    np.testing.assert_array_equal(frame["time"], expected)
    for i in range(3):
        np.testing.assert_array_equal(frame[f"sensor_combined.accelerometer_m_s2[{i}]"], data[f"accelerometer_m_s2[{i}]"].astype(float))
    gps = read_table(ULOG, columns={"position": "vehicle_gps_position.lat"})
    assert len(gps) == 32
    np.testing.assert_array_equal(gps["time"], (ulog.get_dataset("vehicle_gps_position").data["timestamp"].astype(np.int64) - ulog.start_timestamp) * 1e-6)
    assert source_name(ULOG, "imu", gps) == f"{ULOG} topic vehicle_gps_position"
    assert "topics: " in _error(lambda: read_ulog(ULOG, "vehicle_odometry"))


def test_bad_ulogs_are_one_line(tmp_path):
    junk = tmp_path / "junk.ulg"
    junk.write_text("not a log\n")
    assert _error(lambda: read_ulog(junk, "sensor_combined")).startswith(f"{junk}: cannot be read as a ULog: truncated or corrupt (")
    cut = tmp_path / "cut.ulg"
    cut.write_bytes(ULOG.read_bytes()[:100])  # cut inside its definitions: no data at all
    assert _error(lambda: read_ulog(cut, "sensor_combined")) == (
        f"{cut}: cannot be read as a ULog: truncated or corrupt (no data message after its definitions)")


def test_a_ulog_pyulog_finds_corrupt_is_one_line_and_nothing_on_stdout(tmp_path, capsys):
    """pyulog prints "File corruption detected ..." on stdout: captured, and said in the one line."""
    cut = tmp_path / "cut.ulg"
    cut.write_bytes(ULOG.read_bytes()[:30_000])  # cut inside a definition
    assert _error(lambda: read_ulog(cut, "sensor_combined")) == (
        f"{cut}: cannot be read as a ULog: truncated or corrupt (File corruption detected while reading file definitions!)")
    assert capsys.readouterr().out == ""


def test_a_ulog_without_topic_lists_its_own_topics():
    message = _error(lambda: read_table(ULOG, columns={"accel": "accel"}))
    assert "sensor_combined (1298 messages)" in message and "vehicle_gps_position (32 messages)" in message
    assert "e.g. sensor_combined, vehicle_local_position" not in message  # the log's topics, not an example


@pytest.mark.parametrize("ending, opener", [(".gz", gzip.open), (".bz2", bz2.open), (".xz", lzma.open)])
def test_compressed_csv_reads_as_the_plain_file(tmp_path, ending, opener):
    frame = pd.DataFrame({"time": np.arange(5) / 200.0, "accel": [9.8, 9.81, 9.79, 9.8, 1 / 3]})
    plain = tmp_path / "log.csv"
    frame.to_csv(plain, index=False)
    packed = tmp_path / f"log.csv{ending}"
    with opener(packed, "wb") as handle:
        handle.write(plain.read_bytes())
    pd.testing.assert_frame_equal(read_table(packed), read_table(plain))
    broken = tmp_path / f"broken.csv{ending}"
    broken.write_bytes(packed.read_bytes()[:-12])
    assert _error(lambda: read_table(broken)).startswith(f"{broken}: cannot be read as {ending} compressed CSV: corrupt or truncated (")


@pytest.mark.parametrize("ending", [".gz", ".bz2", ".xz", ".zst"])
@pytest.mark.parametrize("damage", ["junk", "half", "flipped"])
def test_a_damaged_compressed_csv_is_one_line_naming_the_cause(tmp_path, ending, damage):
    """Not a compressed stream, cut in half, a byte flipped in the middle: one DataError line saying
    "corrupt or truncated" (no LZMAError or ZstdError traceback, and a half .zst not "file is empty" nor
    its first half read as the whole log)."""
    import zstandard

    frame = pd.DataFrame({"time": np.arange(20_000) / 200.0, "accel": np.random.default_rng(5).normal(9.81, 0.02, 20_000)})
    text = frame.to_csv(index=False).encode()
    packed = {".gz": gzip.compress, ".bz2": bz2.compress, ".xz": lzma.compress,
              ".zst": zstandard.ZstdCompressor().compress}[ending](text)
    data = {"junk": b"time,accel\n0,1\n" * 4, "half": packed[: len(packed) // 2],
            "flipped": packed[: len(packed) // 2] + bytes([packed[len(packed) // 2] ^ 0xFF]) + packed[len(packed) // 2 + 1:]}[damage]
    path = tmp_path / f"log.csv{ending}"
    path.write_bytes(data)
    assert _error(lambda: read_table(path)).startswith(f"{path}: cannot be read as {ending} compressed CSV: corrupt or truncated (")


def test_zstandard_csv_reads_as_csv(tmp_path):
    import zstandard  # a test dependency: pandas reads .zst through it

    frame = pd.DataFrame({"time": [0.0, 0.005], "accel": [9.8, 9.81]})
    path = tmp_path / "log.csv.zst"
    path.write_bytes(zstandard.ZstdCompressor().compress(frame.to_csv(index=False).encode()))
    pd.testing.assert_frame_equal(read_table(path), frame)


def test_zstandard_csv_without_the_package_says_what_it_needs(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "zstandard", None)  # import zstandard now raises ImportError
    path = tmp_path / "log.csv.zst"
    path.write_bytes(b"\x28\xb5\x2f\xfd")
    assert _error(lambda: read_table(path)) == f"{path}: reading a .zst file needs the zstandard package (pip install zstandard)"


def test_topic_is_refused_for_a_table(tmp_path):
    path = tmp_path / "log.csv"
    path.write_text("time,accel\n0,1\n")
    assert "--topic /imu: applies to a ROS bag or a ULog" in _error(lambda: read_table(path, topic="/imu"))
    assert "unknown file type '.txt.gz'" in _error(lambda: read_table(tmp_path / "log.txt.gz"))


def test_a_ulog_topic_of_several_instances_is_topic_colon_n():
    from pyulog import ULog

    ulog = ULog(str(ULOG))
    second = next(d for d in ulog.data_list if d.name == "sensor_accel" and d.multi_id == 1)
    frame = read_table(ULOG, columns=["sensor_accel:1.x"])
    np.testing.assert_array_equal(frame["sensor_accel:1.x"], second.data["x"].astype(float))
    assert len(read_table(ULOG, topic="sensor_accel")) == len(next(d for d in ulog.data_list if d.name == "sensor_accel").data["x"])


def test_header_stamps_on_another_clock_than_the_recording_lose_no_precision(tmp_path):
    """Stamps on a boot clock (100 s after boot), recorded on the wall clock (1.7e9 s): time starts at 0
    at the first message's stamp and every 5 ms step is exactly the float64 of 5 ms worth of ns (from the
    bag's earliest receive time instead, time[0] would be -1.7e9 s and the steps off by up to 4e-7 s)."""
    n = 2000
    stamps = 100_000_000_000 + np.arange(n, dtype=np.int64) * 5_000_000
    receive = ORIGIN_NS + np.arange(n, dtype=np.int64) * 5_000_000
    bag = write_imu_bag(tmp_path / "clock.bag", stamps, np.zeros((n, 3)), receive_ns=receive)
    frame = read_table(bag, columns=AXES)
    np.testing.assert_array_equal(frame["time"], np.arange(n, dtype=np.int64) * 5_000_000 * 1e-9)
    assert frame["time"].iloc[0] == 0.0 and frame.attrs["time_origin_ns"] == 100_000_000_000


def test_variable_length_arrays_are_left_out(tmp_path):
    """A Float64MultiArray whose data changes length: its ``data`` is not a column (no NaN padding); the
    fixed fields (layout.data_offset) are."""
    from rosbags.typesys import Stores, get_typestore

    types = get_typestore(Stores.ROS1_NOETIC).types
    layout = types["std_msgs/msg/MultiArrayLayout"](dim=[], data_offset=7)
    arrays = [types["std_msgs/msg/Float64MultiArray"](layout=layout, data=np.array(v, dtype=float))
              for v in ([1.0, 2.0], [3.0, 4.0, 5.0], [6.0])]
    stamps, accel = _signal(3)
    bag = write_imu_bag(tmp_path / "v.bag", stamps, accel, extra={"/arr": ("std_msgs/msg/Float64MultiArray", arrays)})
    frame = read_table(bag, topic="/arr")
    assert list(frame.columns) == ["time", "/arr.layout.data_offset"]
    np.testing.assert_array_equal(frame["/arr.layout.data_offset"], [7.0, 7.0, 7.0])
    assert not frame.isna().any().any()


def test_align_origins_puts_topics_on_the_earlier_origin_exactly(tmp_path):
    """Two topics with origins 1.234567891 s apart: the later one's times equal, bit for bit, reading it
    from the earlier origin; a table without origin beside a topic, and a bag's stamps beside a ULog's
    boot clock, are refused in one line."""
    from kalcal.io.logs import align_origins

    stamps, accel = _signal(200)
    late = stamps + 1_234_567_891
    a = read_table(write_imu_bag(tmp_path / "a.bag", stamps, accel), topic="/imu")
    b = read_table(write_imu_bag(tmp_path / "b.bag", late, accel), topic="/imu")
    first, second = align_origins([("a", a["time"].to_numpy(), a.attrs), ("b", b["time"].to_numpy(), b.attrs)])
    np.testing.assert_array_equal(first, a["time"])
    np.testing.assert_array_equal(second, (late - stamps[0]).astype(float) * 1e-9)
    ulog = read_table(ULOG, topic="sensor_combined")
    gps = read_table(ULOG, topic="vehicle_gps_position")
    same = align_origins([("u", ulog["time"].to_numpy(), ulog.attrs), ("g", gps["time"].to_numpy(), gps.attrs)])
    np.testing.assert_array_equal(same[1], gps["time"])  # one log, one origin: unchanged
    assert "different clocks (px4 and ros stamps)" in _error(
        lambda: align_origins([("a", a["time"].to_numpy(), a.attrs), ("u", ulog["time"].to_numpy(), ulog.attrs)]))
    assert _error(lambda: align_origins([("a", a["time"].to_numpy(), a.attrs), ("t.csv", np.arange(3.0), {})])).startswith(
        "t.csv: its times have no absolute origin")
    np.testing.assert_array_equal(align_origins([("x", np.arange(3.0), {}), ("y", np.arange(2.0), {})])[1], [0.0, 1.0])
