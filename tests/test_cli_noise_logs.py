"""``kalcal noise`` and ``calibrate`` on ROS bags and PX4 ULog: the same Allan curve and noise as the same
samples from CSV, three axes with imu.yaml's largest density and filter.toml for --axis only, every
check naming the topic, bad files one line with exit status 2."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from kalcal.cli import app
from tests._logfiles import ORIGIN_NS, float64_messages, odometry_messages, write_imu_bag

ULOG = Path(__file__).resolve().parent / "data" / "px4-ulog" / "sample_log_small.ulg"
RATE = 200.0
STD = np.array([0.02, 0.01, 0.03])  # white noise per sample on x, y, z, m/s^2: z's density is the largest


def _invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)


def _static(n: int = 12_001, seed: int = 11):
    rng = np.random.default_rng(seed)
    stamps = ORIGIN_NS + np.arange(n, dtype=np.int64) * 5_000_000  # 200 Hz
    accel = np.array([0.05, -0.03, 9.81]) + STD * rng.standard_normal((n, 3))
    accel[:, 0] += np.cumsum(2e-3 / np.sqrt(RATE) * rng.standard_normal(n))  # a bias walk on x
    return stamps, accel


@pytest.fixture(scope="module", params=[1, 2], ids=["ros1", "ros2"])
def runs(request, tmp_path_factory):
    """The bag's noise run (three axes, --axis x) and the CSV's of each axis alone."""
    base = tmp_path_factory.mktemp(f"bag{request.param}")
    stamps, accel = _static()
    bag = write_imu_bag(base / ("static.bag" if request.param == 1 else "static"), stamps, accel, ros=request.param)
    result = _invoke("noise", "--imu", bag, "--axis", "x", "--out", base / "bag")
    assert result.exit_code == 0, result.output
    csv = {}
    for i, axis in enumerate("xyz"):
        path = base / f"{axis}.csv"
        pd.DataFrame({"time": (stamps - stamps[0]) * 1e-9, "accel": accel[:, i]}).to_csv(path, index=False, float_format="%.17g")
        assert _invoke("noise", "--imu", path, "--out", base / axis).exit_code == 0
        csv[axis] = base / axis
    return bag, base / "bag", csv


def _summary(folder):
    return json.loads((Path(folder) / "summary.json").read_text())


PARAMETERS = ("accel_noise_std", "velocity_random_walk", "bias_instability", "rate_random_walk", "bias_walk_std")


def test_each_axis_equals_the_same_samples_from_csv(runs):
    bag, out, csv = runs
    summary = _summary(out)
    assert summary["topic"] == "/imu" and summary["axis"] == "x"
    for axis in "xyz":
        block, alone = summary["axes"][axis], _summary(csv[axis])
        assert block["column"] == f"/imu.linear_acceleration.{axis}"
        assert block["allan"] == alone["allan"]
        for key in (*PARAMETERS, "mean", "std", "filter", "per_sample"):
            assert block[key] == alone[key], (axis, key)
    assert summary["rate"] == _summary(csv["x"])["rate"]


def test_filter_toml_is_the_selected_axis_and_imu_yaml_the_largest_density(runs):
    bag, out, csv = runs
    settings = tomllib.loads((out / "filter.toml").read_text())["filter"]
    assert settings == tomllib.loads((csv["x"] / "filter.toml").read_text())["filter"]
    assert "axis x (/imu.linear_acceleration.x)" in (out / "filter.toml").read_text()
    densities = {a: _summary(csv[a])["velocity_random_walk"]["value"] for a in "xyz"}
    assert max(densities, key=densities.get) == "z"
    yaml = (out / "imu.yaml").read_text()
    assert f"accelerometer_noise_density: {densities['z']:.6g}  #" in yaml
    assert "the largest of the 3 axes'" in yaml and "rostopic: /imu" in yaml
    allan = pd.read_csv(out / "allan.csv")
    assert list(allan["axis"].unique()) == ["x", "y", "z"]


def test_without_axis_no_filter_toml_and_a_note(runs, tmp_path):
    bag, _, _ = runs
    result = _invoke("noise", "--imu", bag, "--out", tmp_path / "o")
    assert result.exit_code == 0, result.output
    assert not (tmp_path / "o" / "filter.toml").exists()
    assert any(note.startswith("filter.toml not written") for note in _summary(tmp_path / "o")["notes"])
    assert "select it with --axis" in " ".join(result.stdout.split())


def test_one_named_column_of_a_bag_is_a_csv_run(runs, tmp_path):
    """accel=TOPIC.FIELD reads one column, with the single-axis summary's keys and values."""
    bag, _, csv = runs
    result = _invoke("noise", "--imu", bag, "--imu-columns", "accel=/imu.linear_acceleration.y", "--out", tmp_path / "y")
    assert result.exit_code == 0, result.output
    one, alone = _summary(tmp_path / "y"), _summary(csv["y"])
    assert one.keys() == alone.keys()
    for key in (*PARAMETERS, "allan", "filter", "samples"):
        assert one[key] == alone[key]
    assert one["imu"] == f"{bag} topic /imu"


def _refused(*args) -> str:
    result = _invoke(*args)
    assert result.exit_code == 2, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    return lines[0]


def test_bad_bags_one_line_exit_2(tmp_path):
    stamps, accel = _static(400)
    bag = write_imu_bag(tmp_path / "b.bag", stamps, accel, extra={
        "/value": ("std_msgs/msg/Float64", float64_messages(1, [1.0])), "/none": ("std_msgs/msg/Float64", [])})
    out = tmp_path / "o"
    assert "no topic /imu0 (topics: /imu (sensor_msgs/msg/Imu, 400 messages), /none" in _refused("noise", "--imu", bag, "--topic", "/imu0", "--out", out)
    assert "topic /value holds std_msgs/msg/Float64 messages, expected sensor_msgs/msg/Imu" in _refused("noise", "--imu", bag, "--topic", "/value", "--out", out)
    assert "topic /none has no messages" in _refused("noise", "--imu", bag, "--imu-columns", "accel=/none.data", "--out", out)
    truncated = tmp_path / "cut.bag"
    truncated.write_bytes(bag.read_bytes()[:5000])
    assert "cannot be read as a ROS 1 bag" in _refused("noise", "--imu", truncated, "--out", out)
    empty = write_imu_bag(tmp_path / "e.bag", stamps[:0], accel[:0])
    assert "topic /imu has no messages" in _refused("noise", "--imu", empty, "--out", out)
    assert "--axis 'w': expected one of x, y, z" in _refused("noise", "--imu", bag, "--axis", "w", "--out", out)
    csv = tmp_path / "one.csv"
    pd.DataFrame({"time": np.arange(400) / RATE, "accel": accel[:, 0]}).to_csv(csv, index=False)
    assert "--axis x: selects one of a ROS bag's or ULog's three" in _refused("noise", "--imu", csv, "--axis", "x", "--out", out)
    assert not out.exists()


def test_every_check_names_the_topic(tmp_path):
    """Non-monotone stamps, a gap, times in ms (rate), a value beyond the limit: each names file and topic."""
    stamps, accel = _static(2000)
    out = tmp_path / "o"
    back = stamps.copy()
    back[7] = back[5]
    bag = write_imu_bag(tmp_path / "dup.bag", back, accel, receive_ns=stamps)
    assert _refused("noise", "--imu", bag, "--out", out).endswith(
        f"{bag} topic /imu: row 8, column 'time': time 0.025 does not increase (previous row 0.03)")
    gap = stamps.copy()
    gap[1000:] += 50_000_000
    bag = write_imu_bag(tmp_path / "gap.bag", gap, accel)
    assert f"{bag} topic /imu: row 1001, column 'time': step" in _refused("noise", "--imu", bag, "--out", out)
    slow = ORIGIN_NS + np.arange(2000, dtype=np.int64) * 5_000_000_000  # a 0.2 Hz "IMU": 5 s steps
    bag = write_imu_bag(tmp_path / "slow.bag", slow, accel)
    assert f"{bag} topic /imu: column 'time': accelerometer sample rate 0.2 Hz" in _refused("noise", "--imu", bag, "--out", out)
    wild = accel.copy()
    wild[3, 2] = 1e9
    bag = write_imu_bag(tmp_path / "wild.bag", stamps, wild)
    assert f"{bag} topic /imu: row 4, column '/imu.linear_acceleration.z'" in _refused("noise", "--imu", bag, "--out", out)


def test_the_real_ulog_is_read_and_its_gap_refused_naming_the_topic(tmp_path):
    """The PX4 log's sensor_combined starts with one 161 ms step among 4.888 ms ones: the Allan deviation's
    even-spacing check refuses it, naming the topic."""
    message = _refused("noise", "--imu", ULOG, "--out", tmp_path / "o")
    assert "sensor_combined" in message
    assert message.endswith(
        f"{ULOG} topic sensor_combined: row 2, column 'time': step 0.161303 s differs from the median step 0.004888 s "
        "by 3.2e+03% (more than 1%): the Allan deviation needs evenly spaced samples")


def test_accel_gps_from_a_bag_says_what_it_takes(tmp_path):
    from rosbags.typesys import Stores, get_typestore

    stamps, accel = _static(400)
    types = get_typestore(Stores.ROS1_NOETIC).types
    fix = types["sensor_msgs/msg/NavSatFix"](
        header=types["std_msgs/msg/Header"](seq=0, stamp=types["builtin_interfaces/msg/Time"](sec=1, nanosec=0), frame_id="gps"),
        status=types["sensor_msgs/msg/NavSatStatus"](status=0, service=1), latitude=48.1, longitude=11.5, altitude=520.0,
        position_covariance=np.zeros(9), position_covariance_type=0)
    bag = write_imu_bag(tmp_path / "f.bag", stamps, accel, extra={"/fix": ("sensor_msgs/msg/NavSatFix", [fix])})
    message = _refused("calibrate", "accel-gps", "--imu", bag, "--imu-columns", "accel=/imu.linear_acceleration.x",
                       "--gps", bag, "--gps-columns", "position=/fix.latitude,velocity=/fix.velocity", "--out", tmp_path / "o")
    # refused for what a NavSatFix is (geodetic), not only for the velocity it lacks
    assert message.startswith(f"kalcal: error: {bag} topic /fix (sensor_msgs/msg/NavSatFix): position '/fix.latitude' is a "
                              "latitude (degrees, in PX4 also 1e-7 degrees), not a position along the axis of motion in metres: "
                              "accel-gps takes position [m] and velocity [m/s]")
    message = _refused("calibrate", "accel-gps", "--imu", bag, "--imu-columns", "accel=/imu.linear_acceleration.x",
                       "--gps", bag, "--gps-columns", "position=/fix.status.status,velocity=/fix.velocity", "--out", tmp_path / "o")
    assert "(sensor_msgs/msg/NavSatFix): position '/fix.status.status' is a field of a geodetic fix" in message
    assert "name the columns as TOPIC.FIELD" in _refused(
        "calibrate", "accel-gps", "--imu", bag, "--imu-columns", "accel=/imu.linear_acceleration.x", "--gps", bag, "--out", tmp_path / "o")


def test_a_ulog_gps_latitude_is_refused_as_a_position(tmp_path):
    """vehicle_gps_position.lat (1e-7 degrees) taken as metres would calibrate nonsense: refused, naming it."""
    message = _refused("calibrate", "accel-gps", "--imu", ULOG, "--imu-columns", "accel=sensor_combined.accelerometer_m_s2[0]",
                       "--gps", ULOG, "--gps-columns", "position=vehicle_gps_position.lat,velocity=vehicle_gps_position.vel_n_m_s",
                       "--out", tmp_path / "o")
    assert message.startswith(f"kalcal: error: {ULOG} topic vehicle_gps_position: position 'vehicle_gps_position.lat' is a latitude")
    assert not (tmp_path / "o").exists()


def test_accel_gps_from_one_bag_equals_the_same_samples_from_csv(tmp_path):
    """An IMU topic and an Odometry topic of one bag, named as TOPIC.FIELD, calibrate as the same samples
    written to CSV do: both topics on one time origin."""
    sim = tmp_path / "sim"
    assert _invoke("simulate", "accel-gps", "--out", sim, "--set", "scenario.duration=20").exit_code == 0
    imu, gps = pd.read_csv(sim / "imu.csv"), pd.read_csv(sim / "gps.csv")
    imu_ns = ORIGIN_NS + np.round(imu["time"].to_numpy() * 1e9).astype(np.int64)
    gps_ns = ORIGIN_NS + np.round(gps["time"].to_numpy() * 1e9).astype(np.int64)
    accel = np.column_stack([imu["accel"], np.zeros(len(imu)), np.zeros(len(imu))])
    odometry = ("nav_msgs/msg/Odometry", odometry_messages(1, gps_ns, gps["position"], gps["velocity"]), gps_ns)
    bag = write_imu_bag(tmp_path / "drive.bag", imu_ns, accel, extra={"/odom": odometry})
    from kalcal.io.logs import read_table

    frames = {
        "imu": read_table(bag, columns=["/imu.linear_acceleration.x"])[["time", "/imu.linear_acceleration.x"]].set_axis(["time", "accel"], axis=1),
        "gps": read_table(bag, topic="/odom")[["time", "/odom.pose.pose.position.x", "/odom.twist.twist.linear.x"]].set_axis(["time", "position", "velocity"], axis=1),
    }
    # each topic's times start at its own first stamp: on one axis (the IMU's first), as the calibration puts them
    frames["gps"]["time"] = (gps_ns - imu_ns[0]) * 1e-9
    for name, frame in frames.items():
        frame.to_csv(tmp_path / f"{name}.csv", index=False, float_format="%.17g")
    from_csv = _invoke("calibrate", "accel-gps", "--imu", tmp_path / "imu.csv", "--gps", tmp_path / "gps.csv",
                       "--no-settings-sigma", "--out", tmp_path / "csv")
    from_bag = _invoke("calibrate", "accel-gps", "--imu", bag, "--imu-columns", "accel=/imu.linear_acceleration.x",
                       "--gps", bag, "--gps-columns", "position=/odom.pose.pose.position.x,velocity=/odom.twist.twist.linear.x",
                       "--no-settings-sigma", "--out", tmp_path / "bag")
    assert from_csv.exit_code == 0 and from_bag.exit_code == 0, from_csv.output + from_bag.output
    pd.testing.assert_frame_equal(pd.read_csv(tmp_path / "bag" / "estimates.csv"), pd.read_csv(tmp_path / "csv" / "estimates.csv"))
    a, b = _summary(tmp_path / "bag"), _summary(tmp_path / "csv")
    for key in ("bias", "bias_std", "fixes_used", "diagnostics"):
        assert a[key] == b[key], key
    assert a["imu"] == f"{bag} topic /imu" and a["gps"] == f"{bag} topic /odom"


def test_scale_bias_from_a_bag_topic_equals_csv(tmp_path):
    """--reference and --sensor as TOPIC.FIELD of one bag topic (here an Imu's x and y carrying them)."""
    sim = tmp_path / "sim"
    assert _invoke("simulate", "scale-bias", "--out", sim).exit_code == 0
    data = pd.read_csv(sim / "data.csv")
    stamps = ORIGIN_NS + np.round(data["time"].to_numpy() * 1e9).astype(np.int64)
    values = np.column_stack([data["reference"], data["sensor"], np.zeros(len(data))])
    bag = write_imu_bag(tmp_path / "sb.bag", stamps, values)
    from kalcal.io.logs import read_table

    frame = read_table(bag, columns=["/imu.linear_acceleration.x"])
    pd.DataFrame({"time": frame["time"], "reference": frame["/imu.linear_acceleration.x"],
                  "sensor": frame["/imu.linear_acceleration.y"]}).to_csv(tmp_path / "sb.csv", index=False, float_format="%.17g")
    from_csv = _invoke("calibrate", "scale-bias", "--data", tmp_path / "sb.csv", "--out", tmp_path / "csv")
    from_bag = _invoke("calibrate", "scale-bias", "--data", bag, "--reference", "/imu.linear_acceleration.x",
                       "--sensor", "/imu.linear_acceleration.y", "--out", tmp_path / "bag")
    assert from_csv.exit_code == 0 and from_bag.exit_code == 0, from_csv.output + from_bag.output
    a, b = _summary(tmp_path / "bag"), _summary(tmp_path / "csv")
    for key in ("theta", "theta_covariance", "scale_error", "bias", "mean_nis", "consistent", "samples_used"):
        assert a[key] == b[key], key
    assert a["data"] == f"{bag} topic /imu"


def _drive(tmp_path, *settings, late_fixes: int = 0):
    """A simulated accel-gps drive (20 s) as a bag's samples: the IMU's and the GPS's stamps [int ns], the
    accelerometer rows and the Odometry messages of the fixes after the first ``late_fixes``."""
    sim = tmp_path / "sim"
    assert _invoke("simulate", "accel-gps", "--out", sim, "--set", "scenario.duration=20", *settings).exit_code == 0
    imu, gps = pd.read_csv(sim / "imu.csv"), pd.read_csv(sim / "gps.csv").iloc[late_fixes:]
    imu_ns = ORIGIN_NS + np.round(imu["time"].to_numpy() * 1e9).astype(np.int64)
    gps_ns = ORIGIN_NS + np.round(gps["time"].to_numpy() * 1e9).astype(np.int64)
    accel = np.column_stack([imu["accel"], np.zeros(len(imu)), np.zeros(len(imu))])
    odometry = ("nav_msgs/msg/Odometry", odometry_messages(1, gps_ns, gps["position"], gps["velocity"]), gps_ns)
    return imu_ns, gps_ns, accel, odometry, gps


BAG_COLUMNS = ("--imu-columns", "accel=/imu.linear_acceleration.x", "--gps-columns",
               "position=/odom.pose.pose.position.x,velocity=/odom.twist.twist.linear.x")


def test_two_bags_recorded_from_different_starts_equal_one_bag_and_csv(tmp_path):
    """The IMU in one bag, the GPS (its first fix 2.2 s after the IMU's first sample) in another recorded
    from 3 s before its first fix: both on the earlier origin, exactly, so the calibration equals that
    of one bag holding both topics and that of the same samples written to CSV on one time axis."""
    imu_ns, gps_ns, accel, odometry, gps = _drive(tmp_path, late_fixes=10)
    assert gps_ns[0] - imu_ns[0] == 2_200_000_000
    one = write_imu_bag(tmp_path / "one.bag", imu_ns, accel, extra={"/odom": odometry})
    imu_bag = write_imu_bag(tmp_path / "imu.bag", imu_ns, accel)
    start = ("std_msgs/msg/Float64", float64_messages(1, [0.0]), [int(gps_ns[0]) - 3_000_000_000])
    gps_bag = write_imu_bag(tmp_path / "gps.bag", imu_ns[:0], accel[:0], extra={"/odom": odometry, "/start": start})
    pd.DataFrame({"time": (imu_ns - imu_ns[0]) * 1e-9, "accel": accel[:, 0]}).to_csv(tmp_path / "imu.csv", index=False, float_format="%.17g")
    pd.DataFrame({"time": (gps_ns - imu_ns[0]) * 1e-9, "position": gps["position"], "velocity": gps["velocity"]}).to_csv(
        tmp_path / "gps.csv", index=False, float_format="%.17g")
    runs = {"one": (one, one, BAG_COLUMNS), "two": (imu_bag, gps_bag, BAG_COLUMNS),
            "csv": (tmp_path / "imu.csv", tmp_path / "gps.csv", ())}
    for name, (imu, gps_log, columns) in runs.items():
        result = _invoke("calibrate", "accel-gps", "--imu", imu, "--gps", gps_log, *columns, "--no-settings-sigma", "--out", tmp_path / name)
        assert result.exit_code == 0, result.output
    csv = pd.read_csv(tmp_path / "csv" / "estimates.csv")
    for name in ("one", "two"):
        pd.testing.assert_frame_equal(pd.read_csv(tmp_path / name / "estimates.csv"), csv, check_exact=True)
        for key in ("bias", "bias_std", "fixes_used", "diagnostics"):
            assert _summary(tmp_path / name)[key] == _summary(tmp_path / "csv")[key], (name, key)
    # a bag's topic (times from a recorded stamp) with a CSV of relative times: no common origin
    message = _refused("calibrate", "accel-gps", "--imu", imu_bag, "--imu-columns", "accel=/imu.linear_acceleration.x",
                       "--gps", tmp_path / "gps.csv", "--no-settings-sigma", "--out", tmp_path / "mixed")
    assert message == (f"kalcal: error: {tmp_path / 'gps.csv'}: its times have no absolute origin, while {imu_bag} topic /imu's "
                       "are from a recorded stamp: the two logs cannot be aligned (give both as topics of bags or ULogs, "
                       "or both as tables on one time axis)")


def test_the_suggested_fit_command_runs_as_printed(tmp_path):
    """A calibration from bags whose GPS is noisier than the filter assumes (4 m against 1 m): the
    diagnostics say inconsistent and the warning names `kalcal fit accel-gps ...` with the bags' paths
    and the TOPIC.FIELD columns; that command, run as printed, fits."""
    import shlex

    imu_ns, gps_ns, accel, odometry, _ = _drive(tmp_path, "--set", "truth.gps_position_std=4")
    imu_bag = write_imu_bag(tmp_path / "imu.bag", imu_ns, accel)
    gps_bag = write_imu_bag(tmp_path / "gps bag.bag", imu_ns[:0], accel[:0], extra={"/odom": odometry})
    result = _invoke("calibrate", "accel-gps", "--imu", imu_bag, "--gps", gps_bag, *BAG_COLUMNS, "--no-settings-sigma",
                     "--out", tmp_path / "cal")
    assert result.exit_code == 0, result.output
    untrusted = [w["message"] for w in _summary(tmp_path / "cal")["warnings"] if w["code"] == "sigma-untrusted"]
    assert len(untrusted) == 1, _summary(tmp_path / "cal")["warnings"]
    command = untrusted[0].split("`")[1]
    words = shlex.split(command)
    assert words[:3] == ["kalcal", "fit", "accel-gps"] and words[words.index("--gps") + 1] == str(gps_bag)
    words[words.index("--out") + 1] = str(tmp_path / "fit")
    fit = _invoke(*words[1:])
    assert fit.exit_code == 0, fit.output
    fitted = json.loads((tmp_path / "fit" / "fit.json").read_text())
    assert (tmp_path / "fit" / "filter.toml").is_file() and str(imu_bag) in json.dumps(fitted)
