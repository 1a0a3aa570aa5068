"""``kalcal simulate MODEL.toml --data LOG`` and ``kalcal calibrate MODEL.toml --data LOG``: the files, their
columns and keys, --smooth, a ROS bag log, and bad input refused in one line with exit status 2."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd

from tests.scenarios.model_file.test_calibrate_simulate import DIFFUSE, TRACKER, diffuse_log, tracker_log
from tests._helpers import invoke as _invoke, assert_one_line_error as _one_line_error


def _files(tmp_path, text=TRACKER, log=None):
    model = tmp_path / "model.toml"
    model.write_text(text)
    given = tmp_path / "given.csv"
    (tracker_log() if log is None else log).to_csv(given, index=False)
    return model, given


def test_simulate_then_calibrate_with_smooth_writes_the_documented_files(tmp_path):
    model, given = _files(tmp_path)
    result = _invoke("simulate", model, "--data", given, "--seed", 4, "--out", tmp_path / "sim")
    assert result.exit_code == 0, result.output
    truth = json.loads((tmp_path / "sim" / "truth.json").read_text())
    assert truth["seed"] == 4 and truth["rows"] == 120 and truth["true_states"] == ["position_true", "velocity_true"]
    result = _invoke("calibrate", model, "--data", tmp_path / "sim" / "data.csv", "--smooth", "--out", tmp_path / "cal")
    assert result.exit_code == 0, result.output
    assert "log-likelihood" in result.stdout and "position" in result.stdout
    estimates = pd.read_csv(tmp_path / "cal" / "estimates.csv")
    assert list(estimates.columns) == [
        "time", "position", "velocity", "position_std", "velocity_std", "pos_innovation", "pos_innovation_std",
        "vel_innovation", "vel_innovation_std", "nis", "position_smoothed", "position_smoothed_std",
        "velocity_smoothed", "velocity_smoothed_std",
    ]  # fmt: skip
    assert len(estimates) == 120  # one row per row of the log, measured or not
    simulated = pd.read_csv(tmp_path / "sim" / "data.csv")
    np.testing.assert_array_equal(np.isnan(estimates["pos_innovation"]), np.isnan(simulated["pos"]))
    assert estimates["nis"].notna().sum() == (simulated["pos"].notna() | simulated["vel"].notna()).sum()
    summary = json.loads((tmp_path / "cal" / "summary.json").read_text())
    assert summary["scenario"] == "custom" and summary["model"] == "tracker" and summary["smoothed"] is True
    assert summary["estimate"]["position"] == estimates["position"].iloc[-1]
    assert summary["std"]["velocity"] == estimates["velocity_std"].iloc[-1]
    assert summary["settings"]["data"]["inputs"] == ["acc"] and "loglik" in summary and "diffuse_term" in summary
    assert summary["diagnostics"]["consistent"] is True and summary["stability"]["stable"] is True
    assert summary["warnings"] == []


def test_without_smooth_there_are_no_smoothed_columns_and_a_diffuse_file_runs(tmp_path):
    model, given = _files(tmp_path, DIFFUSE, diffuse_log(300))
    assert _invoke("simulate", model, "--data", given, "--seed", 1, "--out", tmp_path / "sim").exit_code == 0
    result = _invoke("calibrate", model, "--data", tmp_path / "sim" / "data.csv", "--out", tmp_path / "cal")
    assert result.exit_code == 0, result.output
    assert "diffuse_term" in result.stdout
    estimates = pd.read_csv(tmp_path / "cal" / "estimates.csv")
    assert not any("smoothed" in c for c in estimates.columns)
    assert np.isnan(estimates["scale"].iloc[0]) and np.isfinite(estimates["scale"].iloc[1])


def test_a_log_whose_constant_jumps_is_not_stable_and_its_sigmas_not_trusted(tmp_path):
    model, given = _files(tmp_path, DIFFUSE, diffuse_log(400))
    assert _invoke("simulate", model, "--data", given, "--seed", 1, "--out", tmp_path / "sim").exit_code == 0
    log = pd.read_csv(tmp_path / "sim" / "data.csv")
    log.loc[200:, "sensor"] += 0.5  # the bias moves by 2.5 sigma of one reading, half-way: 50 sigma of a window's
    log.to_csv(tmp_path / "jumped.csv", index=False)
    result = _invoke("calibrate", model, "--data", tmp_path / "jumped.csv", "--out", tmp_path / "cal", "--strict")
    assert result.exit_code == 1, result.output
    summary = json.loads((tmp_path / "cal" / "summary.json").read_text())
    assert summary["stability"]["stable"] is False and summary["sigma_trusted"] is False
    assert [w["code"] for w in summary["warnings"]] == ["sigma-untrusted"]


def test_a_ros_bag_log(tmp_path):
    from tests._logfiles import write_imu_bag

    rng = np.random.default_rng(0)
    stamps = 1_700_000_000_000_000_000 + np.arange(200) * 10_000_000  # 100 Hz
    x = np.sin(np.arange(200) * 0.05) * 3.0
    accel = np.column_stack([1.01 * x + 0.2 + 0.1 * rng.standard_normal(200), x, np.zeros(200)])
    bag = write_imu_bag(tmp_path / "imu.bag", stamps, accel)
    text = DIFFUSE.split("[truth]")[0] + '\nmeasurement_names = ["x"]\n[data]\ntime = "time"\nmeasurements = ["/imu.linear_acceleration.x"]\n'
    text = text.replace('h = [["reference", 1.0]]', 'h = [["/imu.linear_acceleration.y", 1.0]]').replace("[[0.04]]", "[[0.01]]")
    (tmp_path / "bag.toml").write_text(text)
    result = _invoke("calibrate", tmp_path / "bag.toml", "--data", bag, "--out", tmp_path / "cal")
    assert result.exit_code == 0, result.output
    summary = json.loads((tmp_path / "cal" / "summary.json").read_text())
    assert summary["data"] == f"{bag} topic /imu" and summary["rows"] == 200
    assert abs(summary["estimate"]["scale"] - 1.01) < 4 * summary["std"]["scale"]
    assert abs(summary["estimate"]["bias"] - 0.2) < 4 * summary["std"]["bias"]


def test_calibrate_without_data_is_one_line(tmp_path):
    model, _ = _files(tmp_path)
    _one_line_error(_invoke("calibrate", model, "--out", tmp_path / "cal"), "--data: required to calibrate a model file")


def test_a_missing_column_is_one_line_naming_the_log(tmp_path):
    model, given = _files(tmp_path, log=tracker_log().drop(columns=["acc"]))
    result = _invoke("calibrate", model, "--data", given, "--out", tmp_path / "cal")
    _one_line_error(result, f"{given}: missing column 'acc'")
    assert not (tmp_path / "cal").exists()


def test_a_time_step_off_the_sample_period_is_one_line(tmp_path):
    log = tracker_log()
    log.loc[50:, "t"] += 0.05
    model, given = _files(tmp_path, log=log)
    _one_line_error(_invoke("simulate", model, "--data", given, "--out", tmp_path / "sim"), "row 51, column 't': time step")


def test_an_option_of_the_built_ins_is_one_line(tmp_path):
    model, given = _files(tmp_path)
    _one_line_error(_invoke("calibrate", model, "--data", given, "--gate", 0.99, "--out", tmp_path / "cal"),
                    "--gate: not available for a model file")


def test_a_built_in_refuses_a_log_to_simulate(tmp_path):
    _, given = _files(tmp_path)
    _one_line_error(_invoke("simulate", "scale-bias", "--data", given, "--out", tmp_path / "sim"),
                    "--data: not used by simulate scale-bias (it draws its own logs)")


def _docs() -> str:
    from pathlib import Path

    return (Path(__file__).resolve().parents[1] / "docs" / "custom-models.md").read_text(encoding="utf-8")


def test_the_docs_worked_example_runs_as_written(tmp_path, monkeypatch):
    import shlex

    text = _docs()
    seed003 = next(b for b in text.split("```toml")[1:] if "scale-bias-file" in b).split("```")[0]
    commands = next(b for b in text.split("```sh")[1:] if "seed003.toml" in b).split("```")[0]
    monkeypatch.chdir(tmp_path)
    (tmp_path / "seed003.toml").write_text(seed003)
    diffuse_log(300).to_csv(tmp_path / "given.csv", index=False)
    for line in commands.strip().splitlines():
        words = shlex.split(line)
        assert words[0] == "kalcal"
        result = _invoke(*words[1:])
        assert result.exit_code == 0, result.output
    estimates = pd.read_csv(tmp_path / "cal" / "estimates.csv")
    summary = json.loads((tmp_path / "cal" / "summary.json").read_text())
    # the claims of the worked example: row 0 determines the bias alone, the scale from row 1
    assert np.isnan(estimates.loc[0, "scale"]) and np.isfinite(estimates.loc[0, "bias"])
    assert np.isfinite(estimates.loc[1, "scale"]) and summary["proper_from"]["row"] == 1
    assert {"scale_smoothed", "bias_smoothed_std"} <= set(estimates.columns)
    truth = pd.read_csv(tmp_path / "sim" / "data.csv")[["scale_true", "bias_true"]].iloc[-1].to_numpy()
    for name, value in zip(("scale", "bias"), truth):  # at 4 sigma: a false alarm of 6e-5 a state
        assert abs(summary["estimate"][name] - value) < 4 * summary["std"][name]
    # the messages the docs quote
    no_truth = _invoke("simulate", "seed003.toml", "--data", "given.csv", "--out", "sim2")
    _one_line_error(no_truth, "seed003.toml: its filter starts diffuse in scale, bias and it has no [truth] m0: give "
                              "[truth] m0 (the world's proper prior) to simulate it")
    assert "`seed003.toml: its filter starts diffuse in scale, bias and it has\nno [truth] m0" in text
    _one_line_error(_invoke("calibrate", "seed003.toml", "--data", "given.csv", "--gate", 0.99, "--out", "c2"),
                    "--gate: not available for a model file (seed003.toml) (accel-gps only)")


def test_the_docs_python_calls(tmp_path, monkeypatch):
    import kalcal

    monkeypatch.chdir(tmp_path)
    seed003 = next(b for b in _docs().split("```toml")[1:] if "scale-bias-file" in b).split("```")[0]
    (tmp_path / "seed003.toml").write_text(seed003)
    frame = kalcal.simulate("seed003.toml", seed=1, data=diffuse_log(),
                            settings={"truth.x0": [1.02, 0.3], "truth.m0": [[0.0004, 0.0], [0.0, 0.01]]}).logs["data"]
    result = kalcal.calibrate("seed003.toml", data=frame, smooth=True)
    assert list(result.params.index) == ["scale", "bias"] and list(result.conf_int().index) == ["scale", "bias"]
    np.testing.assert_array_equal(result.bse.to_numpy(), result.estimate_std)


def test_an_output_folder_clash_names_the_model_file_that_wrote_it(tmp_path):
    """The folder records the file, not the name every model file shares: another command (or another file)
    into it is refused naming the file; the same command again replaces its own outputs."""
    model, given = _files(tmp_path)
    out = tmp_path / "out"
    assert _invoke("calibrate", model, "--data", given, "--out", out).exit_code == 0
    assert _invoke("calibrate", model, "--data", given, "--out", out).exit_code == 0  # its own outputs
    expected = f"--out {out}: holds the outputs of `kalcal calibrate a model file ({model})`; choose another folder"
    _one_line_error(_invoke("simulate", model, "--data", given, "--seed", 1, "--out", out), expected)
    _one_line_error(_invoke("fit", model, "--data", given, "--out", out), expected)
    other = tmp_path / "other.toml"
    other.write_text(TRACKER)
    _one_line_error(_invoke("calibrate", other, "--data", given, "--out", out), expected)
    assert "custom" not in expected
    sim = tmp_path / "sim"
    assert _invoke("simulate", model, "--data", given, "--seed", 1, "--out", sim).exit_code == 0
    _one_line_error(_invoke("calibrate", model, "--data", given, "--out", sim),
                    f"holds the outputs of `kalcal simulate a model file ({model})`")
