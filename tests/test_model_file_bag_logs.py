"""A model file over a ROS bag topic (``[data]`` columns as TOPIC.FIELD): calibrate equals the same samples
from CSV (to 1e-12, the same numbers), fit and simulate run from the bag, and the ``kalcal fit`` command a
calibration suggests runs as printed; ``kalcal noise`` on a ULog's sensor_combined."""

from __future__ import annotations

import json
import shlex

import numpy as np
import pandas as pd

from tests._logfiles import ORIGIN_NS, write_imu_bag
from tests._helpers import invoke as _invoke

N = 400


def _model(v: float = 0.01) -> str:
    """A scale and bias of /imu.linear_acceleration.x against the reference in its y, 100 Hz."""
    return f'''
name = "scale-bias-bag"
sample_period = 0.01
phi = [[1.0, 0.0], [0.0, 1.0]]
gamma = [[1.0], [0.0]]
w = [[1e-8]]
h = [["/imu.linear_acceleration.y", 1.0]]
v = [[{v!r}]]
x0 = [0.0, 0.0]
m0 = [[0.0, 0.0], [0.0, 0.0]]
diffuse = ["scale", "bias"]
state_names = ["scale", "bias"]
measurement_names = ["x"]
[truth]
x0 = [1.02, 0.3]
m0 = [[0.0004, 0.0], [0.0, 0.01]]
[data]
time = "time"
measurements = ["/imu.linear_acceleration.x"]
'''


def _bag(tmp_path):
    rng = np.random.default_rng(0)
    stamps = ORIGIN_NS + np.arange(N, dtype=np.int64) * 10_000_000
    x = np.sin(np.arange(N) * 0.05) * 3.0
    accel = np.column_stack([1.01 * x + 0.2 + 0.1 * rng.standard_normal(N), x, np.zeros(N)])
    return write_imu_bag(tmp_path / "imu.bag", stamps, accel), stamps, accel


def test_calibrate_from_a_bag_equals_the_same_samples_from_csv(tmp_path):
    bag, stamps, accel = _bag(tmp_path)
    model = tmp_path / "model.toml"
    model.write_text(_model())
    csv = tmp_path / "imu.csv"
    pd.DataFrame({"time": (stamps - stamps[0]) * 1e-9, "/imu.linear_acceleration.x": accel[:, 0],
                  "/imu.linear_acceleration.y": accel[:, 1]}).to_csv(csv, index=False, float_format="%.17g")
    for name, log in (("bag", bag), ("csv", csv)):
        result = _invoke("calibrate", model, "--data", log, "--out", tmp_path / name)
        assert result.exit_code == 0, result.output
    a, b = (json.loads((tmp_path / name / "summary.json").read_text()) for name in ("bag", "csv"))
    for key in ("scale", "bias"):
        np.testing.assert_allclose(a["estimate"][key], b["estimate"][key], rtol=1e-12, atol=0)
        np.testing.assert_allclose(a["std"][key], b["std"][key], rtol=1e-12, atol=0)
    pd.testing.assert_frame_equal(pd.read_csv(tmp_path / "bag" / "estimates.csv"), pd.read_csv(tmp_path / "csv" / "estimates.csv"),
                                  check_exact=False, rtol=1e-12, atol=0)
    assert a["data"] == f"{bag} topic /imu" and b["data"] == str(csv)


def test_the_suggested_fit_runs_as_printed_and_simulate_takes_the_bag(tmp_path):
    """v 1e-6 against the samples' 0.01 m^2/s^4: inconsistent, so the warning names `kalcal fit ...`
    with the bag's path (not "FILE topic TOPIC"); run as printed it fits from the bag. simulate draws a
    log on the bag's time and reference columns."""
    bag, _, _ = _bag(tmp_path)
    model = tmp_path / "model.toml"
    model.write_text(_model(v=1e-6))
    result = _invoke("calibrate", model, "--data", bag, "--out", tmp_path / "cal")
    assert result.exit_code == 0, result.output
    warnings = json.loads((tmp_path / "cal" / "summary.json").read_text())["warnings"]
    untrusted = [w["message"] for w in warnings if w["code"] == "sigma-untrusted"]
    assert len(untrusted) == 1, warnings
    words = shlex.split(untrusted[0].split("`")[1])
    assert words[:3] == ["kalcal", "fit", str(model)] and words[words.index("--data") + 1] == str(bag)
    words[words.index("--out") + 1] = str(tmp_path / "fit")
    fit = _invoke(*words[1:])
    assert fit.exit_code == 0, fit.output
    assert (tmp_path / "fit" / "model.toml").is_file()
    fitted = json.loads((tmp_path / "fit" / "fit.json").read_text())
    # every row of the bag, less the two that resolve the diffuse scale and bias
    assert fitted["converged"] and fitted["fixes"] == N - 2 and fitted["inputs"]["data"] == f"{bag} topic /imu"
    sim = _invoke("simulate", model, "--data", bag, "--out", tmp_path / "sim")
    assert sim.exit_code == 0, sim.output
    drawn = pd.read_csv(tmp_path / "sim" / "data.csv")
    assert len(drawn) == N and "/imu.linear_acceleration.x" in drawn and "/imu.linear_acceleration.y" in drawn


def test_noise_on_a_ulog_with_axis_z_succeeds_and_equals_csv(tmp_path):
    """The shipped log's sensor_combined has a 161 ms first step and 1% jitter (refused for the Allan
    deviation): written again by pyulog's own writer with the first message left out and each
    accelerometer time put on the median 4888 us grid (accelerometer_timestamp_relative moved), its real
    samples run through ``kalcal noise --imu FILE.ulg --axis z`` and equal the same samples from CSV."""
    from pyulog import ULog

    from tests.test_cli_noise_logs import ULOG

    ulog = ULog(str(ULOG))
    data = next(d for d in ulog.data_list if d.name == "sensor_combined").data
    for key in list(data):
        data[key] = data[key][1:]
    stamps = data["timestamp"].astype(np.int64)
    grid = stamps[0] + data["accelerometer_timestamp_relative"][0] + 4888 * np.arange(stamps.size, dtype=np.int64)
    data["accelerometer_timestamp_relative"] = (grid - stamps).astype(data["accelerometer_timestamp_relative"].dtype)
    path = tmp_path / "even.ulg"
    ulog.write_ulog(str(path))
    result = _invoke("noise", "--imu", path, "--axis", "z", "--out", tmp_path / "ulg")
    assert result.exit_code == 0, result.output
    summary = json.loads((tmp_path / "ulg" / "summary.json").read_text())
    assert summary["topic"] == "sensor_combined" and summary["axis"] == "z" and summary["samples"] == stamps.size
    assert "axis z (sensor_combined.accelerometer_m_s2[2])" in (tmp_path / "ulg" / "filter.toml").read_text()
    csv = tmp_path / "z.csv"
    pd.DataFrame({"time": (grid - ulog.start_timestamp) * 1e-6, "accel": data["accelerometer_m_s2[2]"].astype(float)}).to_csv(
        csv, index=False, float_format="%.17g")
    assert _invoke("noise", "--imu", csv, "--out", tmp_path / "csv").exit_code == 0
    alone = json.loads((tmp_path / "csv" / "summary.json").read_text())
    for key in ("allan", "velocity_random_walk", "accel_noise_std", "filter"):
        assert summary["axes"]["z"][key] == alone[key], key
