"""The ``kalcal`` command line: files written, summaries, and one-line errors with exit status 2."""

from __future__ import annotations

import json
import re

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from kalcal.scenarios.accel_gps.calibration import calibrate_accel_gps
from kalcal.cli import app
from kalcal.scenarios import build_scenario
from kalcal.scenarios.accel_gps.sampled import sample_accel_gps_logs

ESTIMATE_COLUMNS = [
    "time", "position", "velocity", "bias", "position_std", "velocity_std", "bias_std",
    "nis", "innovation_position", "innovation_velocity",
]
SUMMARY_KEYS = {"bias", "bias_std", "position", "velocity", "covariance", "fixes_used", "diagnostics"}


def _invoke(*args: str):
    # click >= 8.2 keeps stdout and stderr apart on the result (there is no mix_stderr argument).
    return CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim")
    result = _invoke("simulate", "accel-gps", "--seed", "1", "--out", out)
    assert result.exit_code == 0, result.output + result.stderr
    return out


@pytest.fixture(scope="module")
def calibrated(simulated, tmp_path_factory):
    out = tmp_path_factory.mktemp("cal")
    # the study's bias prior, given explicitly (a log's default is diffuse): the library's default calibration
    result = _invoke(
        "calibrate", "accel-gps", "--imu", simulated / "imu.csv", "--gps", simulated / "gps.csv", "--out", out,
        "--set", "filter.bias_std=0.1",
    )
    assert result.exit_code == 0, result.output + result.stderr
    return out, result


def test_simulate_writes_the_logs(simulated):
    imu = pd.read_csv(simulated / "imu.csv")
    gps = pd.read_csv(simulated / "gps.csv")
    truth = pd.read_csv(simulated / "truth.csv")
    assert list(imu.columns) == ["time", "accel"] and len(imu) == 6001
    assert list(gps.columns) == ["time", "position", "velocity"] and len(gps) == 150
    assert list(truth.columns[:3]) == ["time", "position", "velocity"] and len(truth) == 6001
    assert {"accel", "bias"} <= set(truth.columns)
    assert gps["time"].iloc[0] == pytest.approx(0.2, rel=1e-12)
    assert gps["time"].iloc[-1] == pytest.approx(30.0, rel=1e-12)
    assert imu["time"].iloc[0] == 0.0 and imu["time"].iloc[-1] == pytest.approx(30.0, rel=1e-12)
    # The files hold, to the last bit, realization 0 of the sampler with generator seed 1.
    logs = sample_accel_gps_logs(build_scenario("accel-gps"), np.random.default_rng(1), 1)
    np.testing.assert_array_equal(imu["accel"].to_numpy(), logs.accel[0])
    np.testing.assert_array_equal(gps["position"].to_numpy(), logs.gps_position[0])
    np.testing.assert_array_equal(truth["bias"].to_numpy(), logs.bias[0])


def test_simulate_is_reproducible_and_seed_dependent(simulated, tmp_path):
    again, other = tmp_path / "again", tmp_path / "other"
    assert _invoke("simulate", "accel-gps", "--seed", "1", "--out", again).exit_code == 0
    assert _invoke("simulate", "accel-gps", "--seed", "2", "--out", other).exit_code == 0
    assert (again / "imu.csv").read_bytes() == (simulated / "imu.csv").read_bytes()
    assert (other / "imu.csv").read_bytes() != (simulated / "imu.csv").read_bytes()


def test_simulate_honours_settings(tmp_path):
    result = _invoke("simulate", "accel-gps", "--seed", "3", "--out", tmp_path, "--set", "scenario.duration=2")
    assert result.exit_code == 0, result.stderr
    assert len(pd.read_csv(tmp_path / "imu.csv")) == 401
    assert len(pd.read_csv(tmp_path / "gps.csv")) == 10


def test_calibrate_writes_estimates_and_summary(simulated, calibrated):
    out, result = calibrated
    estimates = pd.read_csv(out / "estimates.csv")
    assert list(estimates.columns) == ESTIMATE_COLUMNS
    assert len(estimates) == 149  # the first fix starts the nominal
    summary = json.loads((out / "summary.json").read_text())
    assert SUMMARY_KEYS <= set(summary)
    assert summary["fixes_used"] == 149 and summary["init"] == "first-fix"
    covariance = np.array(summary["covariance"])
    assert covariance.shape == (3, 3)
    np.testing.assert_allclose(covariance, covariance.T, rtol=0, atol=0)
    assert summary["bias"] == estimates["bias"].iloc[-1]
    assert summary["bias_std"] == pytest.approx(np.sqrt(covariance[2, 2]), rel=1e-12)
    assert summary["bias_std"] == estimates["bias_std"].iloc[-1]
    # The summary is the library's calibration (the CLI defaults to the trapezoid rule for logs).
    imu, gps = pd.read_csv(simulated / "imu.csv"), pd.read_csv(simulated / "gps.csv")
    scenario = build_scenario("accel-gps", assignments=["scenario.integration=trapezoid"])
    direct = calibrate_accel_gps(
        scenario,
        *(imu[c].to_numpy() for c in ("time", "accel")),
        *(gps[c].to_numpy() for c in ("time", "position", "velocity")),
        init="first-fix",
    )
    assert summary["bias"] == direct.bias[-1]
    assert summary["position"] == direct.position[-1] and summary["velocity"] == direct.velocity[-1]
    assert summary["settings"]["scenario"]["integration"] == "trapezoid"
    # The estimate is within 4 sigma of the simulated bias.
    true_bias = pd.read_csv(simulated / "truth.csv")["bias"].iloc[0]
    assert abs(summary["bias"] - true_bias) <= 4 * summary["bias_std"]
    assert "bias" in result.stdout and result.stderr == ""


def test_calibrate_integration_can_be_set(simulated, calibrated, tmp_path):
    out, _ = calibrated
    result = _invoke(
        "calibrate", "accel-gps", "--imu", simulated / "imu.csv", "--gps", simulated / "gps.csv", "--out", tmp_path,
        "--set", "scenario.integration=euler", "--set", "filter.bias_std=0.1",
    )
    assert result.exit_code == 0, result.stderr
    euler = json.loads((tmp_path / "summary.json").read_text())
    trapezoid = json.loads((out / "summary.json").read_text())
    assert euler["settings"]["scenario"]["integration"] == "euler"
    assert euler["bias"] != trapezoid["bias"]
    np.testing.assert_allclose(euler["covariance"], trapezoid["covariance"], rtol=1e-12)


def test_config_file_is_read(simulated, calibrated, tmp_path):
    config = tmp_path / "c.toml"
    config.write_text("[filter]\ngps_position_std = 2.0\n")
    result = _invoke(
        "calibrate", "accel-gps", "--imu", simulated / "imu.csv", "--gps", simulated / "gps.csv",
        "--out", tmp_path / "o", "--config", config, "--set", "filter.bias_std=0.1",
    )
    assert result.exit_code == 0, result.stderr
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["settings"]["filter"]["gps_position_std"] == 2.0
    base = json.loads((calibrated[0] / "summary.json").read_text())
    assert summary["position_std"] > base["position_std"]


def test_parquet_input_gives_the_same_summary(simulated, calibrated, tmp_path):
    for name in ("imu", "gps"):
        pd.read_csv(simulated / f"{name}.csv").to_parquet(tmp_path / f"{name}.parquet")
    result = _invoke(
        "calibrate", "accel-gps", "--imu", tmp_path / "imu.parquet", "--gps", tmp_path / "gps.parquet", "--out", tmp_path / "o",
        "--set", "filter.bias_std=0.1",
    )
    assert result.exit_code == 0, result.stderr
    from_parquet = json.loads((tmp_path / "o" / "summary.json").read_text())
    from_csv = json.loads((calibrated[0] / "summary.json").read_text())
    for key in ("imu", "gps"):
        from_parquet.pop(key)
        from_csv.pop(key)
    assert from_parquet == from_csv
    assert (tmp_path / "o" / "estimates.csv").read_text() == (calibrated[0] / "estimates.csv").read_text()


# --------------------------------------------------------------------------------------------------
# bad input: exit status 2 and one line on stderr naming the problem


@pytest.fixture(scope="module")
def short_logs(simulated, tmp_path_factory):
    """The first second of the simulated logs (201 samples, 5 fixes), as data frames."""
    imu = pd.read_csv(simulated / "imu.csv").iloc[:201].copy()
    gps = pd.read_csv(simulated / "gps.csv").iloc[:5].copy()
    return imu, gps


def _csv(frame, path):
    frame.to_csv(path, index=False, float_format="%.17g")
    return path


def _imu_with(imu, row, column, value):
    bad = imu.astype({column: object})
    bad.iloc[row, bad.columns.get_loc(column)] = value
    return bad


CASES = {
    "missing file": (lambda imu, gps, d: (d / "nope.csv", _csv(gps, d / "gps.csv"), []), r"nope\.csv: no such file"),
    "empty file": (
        lambda imu, gps, d: ((d / "imu.csv").write_text("") or d / "imu.csv", _csv(gps, d / "gps.csv"), []),
        r"imu\.csv: file is empty",
    ),
    "header only": (
        lambda imu, gps, d: (_csv(imu.iloc[:0], d / "imu.csv"), _csv(gps, d / "gps.csv"), []),
        r"imu\.csv: has a header but no data rows",
    ),
    "missing column": (
        lambda imu, gps, d: (_csv(imu, d / "imu.csv"), _csv(gps.drop(columns="velocity"), d / "gps.csv"), []),
        r"gps\.csv: missing column 'velocity'",
    ),
    "non-numeric cell": (
        lambda imu, gps, d: (_csv(_imu_with(imu, 2, "accel", "abc"), d / "imu.csv"), _csv(gps, d / "gps.csv"), []),
        r"imu\.csv: row 3, column 'accel': not a number: 'abc'",
    ),
    "nan accel": (
        lambda imu, gps, d: (_csv(_imu_with(imu, 4, "accel", np.nan), d / "imu.csv"), _csv(gps, d / "gps.csv"), []),
        r"imu\.csv: row 5, column 'accel': .*finite",
    ),
    "inf accel": (
        lambda imu, gps, d: (_csv(_imu_with(imu, 6, "accel", np.inf), d / "imu.csv"), _csv(gps, d / "gps.csv"), []),
        r"imu\.csv: row 7, column 'accel': .*finite",
    ),
    "non-increasing time": (
        lambda imu, gps, d: (_csv(_imu_with(imu, 10, "time", 0.045), d / "imu.csv"), _csv(gps, d / "gps.csv"), []),
        r"imu\.csv: row 11, column 'time'.*does not increase",
    ),
    "non-increasing gps time": (
        lambda imu, gps, d: (_csv(imu, d / "imu.csv"), _csv(_imu_with(gps, 3, "time", 0.6), d / "gps.csv"), []),
        r"gps\.csv: row 4, column 'time'.*does not increase",
    ),
    "unknown set key": (
        lambda imu, gps, d: (_csv(imu, d / "imu.csv"), _csv(gps, d / "gps.csv"), ["--set", "truth.nope=1"]),
        r"truth\.nope: expected a setting of \[truth\] .*, got an unknown key",
    ),
    "unknown set section": (
        lambda imu, gps, d: (_csv(imu, d / "imu.csv"), _csv(gps, d / "gps.csv"), ["--set", "nope.x=1"]),
        r"nope\.x: expected a setting of .*, got an unknown section",
    ),
    "bad set value": (
        lambda imu, gps, d: (_csv(imu, d / "imu.csv"), _csv(gps, d / "gps.csv"), ["--set", "filter.bias_std=big"]),
        r"filter\.bias_std: expected a number, got 'big'",
    ),
    "set without equals": (
        lambda imu, gps, d: (_csv(imu, d / "imu.csv"), _csv(gps, d / "gps.csv"), ["--set", "filter.bias_std"]),
        r"expected section\.key=value",
    ),
    "negative noise setting": (
        lambda imu, gps, d: (_csv(imu, d / "imu.csv"), _csv(gps, d / "gps.csv"), ["--set", "filter.gps_position_std=-1"]),
        r"filter\.gps_position_std: expected a positive number, got -1",
    ),
    "missing config": (
        lambda imu, gps, d: (_csv(imu, d / "imu.csv"), _csv(gps, d / "gps.csv"), ["--config", str(d / "no.toml")]),
        r"no\.toml: expected a readable config file, got no such file",
    ),
    "no overlap between the logs": (
        lambda imu, gps, d: (_csv(imu, d / "imu.csv"), _csv(gps.assign(time=gps["time"] + 100.0), d / "gps.csv"), []),
        r"gps\.csv: no fix lies within the accelerometer log",
    ),
    # the CLI's first-fix start and diffuse bias need a third fix to check the filter against
    "fewer than three fixes": (
        lambda imu, gps, d: (_csv(imu, d / "imu.csv"), _csv(gps.iloc[:2], d / "gps.csv"), []),
        r"gps\.csv: needs at least three usable fixes .*got 2.*no fix to check",
    ),
    "single accelerometer sample": (
        lambda imu, gps, d: (_csv(imu.iloc[:1], d / "imu.csv"), _csv(gps, d / "gps.csv"), []),
        r"imu\.csv: needs at least two accelerometer samples",
    ),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_input_is_one_line_and_exit_status_2(case, short_logs, tmp_path):
    make, pattern = CASES[case]
    imu_path, gps_path, extra = make(*short_logs, tmp_path)
    out = tmp_path / "out"
    result = _invoke("calibrate", "accel-gps", "--imu", imu_path, "--gps", gps_path, "--out", out, *extra)
    assert result.exit_code == 2, (result.exit_code, result.stdout, result.stderr)
    message = result.stderr.rstrip("\n")
    assert "\n" not in message, f"not one line: {message!r}"
    assert message.startswith("kalcal: error: ")
    assert re.search(pattern, message), message
    assert "Traceback" not in result.stdout + result.stderr
    assert not (out / "summary.json").exists()


def test_short_logs_themselves_are_fine(short_logs, tmp_path):
    imu, gps = short_logs
    result = _invoke(
        "calibrate", "accel-gps", "--imu", _csv(imu, tmp_path / "imu.csv"), "--gps", _csv(gps, tmp_path / "gps.csv"),
        "--out", tmp_path / "out",
    )
    assert result.exit_code == 0, result.stderr
    # recorded data start from the first fix, which is then not an update
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["fixes_used"] == 4


def test_simulate_bad_setting_is_exit_status_2(tmp_path):
    result = _invoke("simulate", "accel-gps", "--out", tmp_path, "--set", "scenario.truth=foo")
    assert result.exit_code == 2
    assert result.stderr.count("\n") <= 1 and "scenario.truth" in result.stderr and "'foo'" in result.stderr
    assert not (tmp_path / "imu.csv").exists()


def test_unknown_scenario_is_exit_status_2(tmp_path):
    result = _invoke("simulate", "nope", "--out", tmp_path)
    assert result.exit_code == 2
    assert "SCENARIO: expected one of accel-gps, scale-bias, imu-3axis, got 'nope'" in result.stderr


# --------------------------------------------------------------------------------------------------
# regressions of bugs found when this suite was written


def test_a_stopping_accelerometer_gap_names_the_imu_file(short_logs, tmp_path):
    imu, gps = short_logs
    gapped = imu.drop(index=range(100, 110))
    result = _invoke(
        "calibrate", "accel-gps", "--imu", _csv(gapped, tmp_path / "gapped_imu.csv"), "--gps",
        _csv(gps, tmp_path / "gps.csv"), "--out", tmp_path / "out", "--on-gap", "stop",
    )
    assert result.exit_code == 2
    assert "gap" in result.stderr and "--max-imu-gap" in result.stderr
    assert "gapped_imu.csv" in result.stderr, result.stderr


def test_out_path_that_is_a_file_is_exit_status_2(short_logs, tmp_path):
    imu, gps = short_logs
    blocker = tmp_path / "not_a_directory"
    blocker.write_text("")
    result = CliRunner().invoke(
        app,
        ["calibrate", "accel-gps", "--imu", str(_csv(imu, tmp_path / "imu.csv")), "--gps",
         str(_csv(gps, tmp_path / "gps.csv")), "--out", str(blocker)],
    )
    assert result.exit_code == 2
    assert result.stderr.count("\n") <= 1 and "not_a_directory" in result.stderr


def test_console_script_usage_errors_are_one_line_with_status_2():
    """Errors of the option parser itself (not kalcal's own checks) go through main() too."""
    import subprocess
    import sys

    for args in (["verify", "-n", "abc"], ["verify", "--bogus"], ["calibrate"]):
        done = subprocess.run([sys.executable, "-m", "kalcal.cli", *args], capture_output=True, text=True)
        assert done.returncode == 2, (args, done.stderr)
        lines = [line for line in done.stderr.splitlines() if line.strip()]
        assert len(lines) == 1 and lines[0].startswith("kalcal: error: "), (args, done.stderr)
    done = subprocess.run([sys.executable, "-m", "kalcal.cli"], capture_output=True, text=True)
    assert done.returncode == 0 and "Usage" in done.stdout
