"""``--topic`` for a model file's commands over a ROS bag: calibrate, fit, simulate, verify and analyze
``--data BAG --topic T`` read topic T, and one file whose columns name fields alone reads either of two
topics of one message type. Bad uses of ``--topic`` are one line on stderr with exit status 2."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from tests._helpers import invoke as _invoke, assert_one_line_error as _one_line_error

#: the bag's two IMU topics: reference_k = scale * sensor_k + bias + noise, each topic its own scale and bias
TOPICS = {"/imu": (1.01, 0.2), "/imu_b": (0.97, -0.3)}
ROWS = 200
NOISE = 0.1  # the reference's std (v = 0.01)

#: the scale-bias file over an IMU topic, its columns named by field alone: the reference is x, the sensor y
FIELDS = """
name = "imu-scale-bias"
sample_period = 0.01
phi = [[1.0, 0.0], [0.0, 1.0]]
gamma = [[1.0], [0.0]]
w = [[0.0]]
h = [["linear_acceleration.y", 1.0]]
v = [[0.01]]
x0 = [1.0, 0.0]
m0 = [[1.0, 0.0], [0.0, 1.0]]
state_names = ["scale", "bias"]
measurement_names = ["x"]

[data]
time = "time"
measurements = ["linear_acceleration.x"]
"""


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    """A ROS 1 bag with two sensor_msgs/Imu topics at 100 Hz, written by rosbags."""
    from tests._logfiles import _imu, _typestore, write_imu_bag

    rng = np.random.default_rng(0)
    stamps = 1_700_000_000_000_000_000 + np.arange(ROWS) * 10_000_000
    signal = 3.0 * np.sin(np.arange(ROWS) * 0.05)

    def accel(scale, bias):
        return np.column_stack([scale * signal + bias + NOISE * rng.standard_normal(ROWS), signal, np.zeros(ROWS)])

    ts = _typestore(1)
    other = [_imu(ts, int(s), row, i) for i, (s, row) in enumerate(zip(stamps, accel(*TOPICS["/imu_b"])))]
    path = tmp_path_factory.mktemp("bag") / "two.bag"
    write_imu_bag(path, stamps, accel(*TOPICS["/imu"]), extra={"/imu_b": ("sensor_msgs/msg/Imu", other, list(stamps))})
    model = path.parent / "fields.toml"
    model.write_text(FIELDS)
    return path, model


@pytest.mark.parametrize("topic", list(TOPICS))
def test_calibrate_reads_the_topic_it_is_given(tmp_path, bag, topic):
    path, model = bag
    result = _invoke("calibrate", model, "--data", path, "--topic", topic, "--out", tmp_path / "cal")
    assert result.exit_code == 0, result.output
    summary = json.loads((tmp_path / "cal" / "summary.json").read_text())
    assert summary["data"] == f"{path} topic {topic}" and summary["rows"] == ROWS
    # each topic's own scale and bias within 4 sigma (a false alarm of 6e-5 per estimate), and not the other's:
    # the two biases differ by 0.5, 70 sigma of either estimate (0.007)
    (scale, bias), (_, other_bias) = TOPICS[topic], [v for k, v in TOPICS.items() if k != topic][0]
    estimate, std = summary["estimate"], summary["std"]
    assert abs(estimate["scale"] - scale) < 4 * std["scale"] and abs(estimate["bias"] - bias) < 4 * std["bias"]
    assert abs(estimate["bias"] - other_bias) > 20 * std["bias"]


def test_fit_simulate_verify_and_analyze_take_the_topic(tmp_path, bag):
    path, model = bag
    result = _invoke("fit", model, "--data", path, "--topic", "/imu_b", "--free", "filter.v", "--out", tmp_path / "fit")
    assert result.exit_code == 0, result.output
    fitted = json.loads((tmp_path / "fit" / "fit.json").read_text())["parameters"]["filter.v"]
    # the reference's variance 0.01 inside the 95% interval (a miss is the interval's 5%, fixed seed)
    assert fitted["ci_low"] < NOISE**2 < fitted["ci_high"]

    result = _invoke("simulate", model, "--data", path, "--topic", "/imu_b", "--seed", 2, "--out", tmp_path / "sim")
    assert result.exit_code == 0, result.output
    truth = json.loads((tmp_path / "sim" / "truth.json").read_text())
    assert truth["data"] == f"{path} topic /imu_b" and truth["rows"] == ROWS
    simulated = pd.read_csv(tmp_path / "sim" / "data.csv")
    # the log in the file's layout: its columns as the file names them (fields alone), the h column copied
    assert list(simulated.columns) == ["time", "linear_acceleration.x", "linear_acceleration.y", "scale_true", "bias_true"]
    np.testing.assert_allclose(simulated["linear_acceleration.y"], 3.0 * np.sin(np.arange(ROWS) * 0.05), rtol=0, atol=1e-12)

    result = _invoke("verify", model, "--data", path, "--topic", "/imu_b", "-n", 2000, "--no-report", "--out", tmp_path / "ver")
    assert result.exit_code == 0, result.output
    summary = json.loads((tmp_path / "ver" / "summary.json").read_text())
    assert summary["settings"]["log"]["topic"] == "/imu_b"
    result = _invoke("analyze", model, "--data", path, "--topic", "/imu", "--out", tmp_path / "ana")
    assert result.exit_code == 0, result.output


def test_without_a_topic_a_field_alone_is_one_line_listing_the_topics(tmp_path, bag):
    path, model = bag
    result = _invoke("calibrate", model, "--data", path, "--out", tmp_path / "cal")
    _one_line_error(result, "topics: /imu (sensor_msgs/msg/Imu, 200 messages), /imu_b (sensor_msgs/msg/Imu, 200 messages)")


def test_a_topic_the_bag_lacks_a_csv_or_a_built_in_is_one_line(tmp_path, bag):
    path, model = bag
    _one_line_error(_invoke("calibrate", model, "--data", path, "--topic", "/gps", "--out", tmp_path / "a"), "/gps")
    csv = tmp_path / "log.csv"
    pd.DataFrame({"time": [0.0, 0.01], "linear_acceleration.x": [1.0, 2.0], "linear_acceleration.y": [1.0, 2.0]}).to_csv(csv, index=False)
    _one_line_error(_invoke("calibrate", model, "--data", csv, "--topic", "/imu", "--out", tmp_path / "b"),
                    "--topic /imu: applies to a ROS bag or a ULog")
    _one_line_error(_invoke("calibrate", "scale-bias", "--data", csv, "--topic", "/imu", "--out", tmp_path / "c"),
                    "--topic: read by a model file's [data] table only")
    _one_line_error(_invoke("verify", model, "--topic", "/imu", "-n", 100, "--out", tmp_path / "d"), "no --data is given")
