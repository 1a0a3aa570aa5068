"""``--windows`` in ``kalcal calibrate`` and ``kalcal.calibrate``: summary.json's ``stability``, one terminal
line, bad values as one line with exit status 2."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

import kalcal
from kalcal.cli import app

STABILITY_KEYS = {"windows", "parameters", "units", "model", "prior", "statistic", "dof", "p_value", "level", "stable", "sentence"}


def _invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim")
    assert _invoke("simulate", "accel-gps", "--seed", "2", "--out", out / "ag").exit_code == 0
    assert _invoke("simulate", "scale-bias", "--seed", "2", "--out", out / "sb").exit_code == 0
    return out


def test_accel_gps_summary_and_terminal_line(logs, tmp_path):
    result = _invoke(
        "calibrate", "accel-gps", "--imu", logs / "ag" / "imu.csv", "--gps", logs / "ag" / "gps.csv",
        "--windows", "3", "--out", tmp_path,
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    stability = json.loads((tmp_path / "summary.json").read_text())["stability"]
    assert set(stability) == STABILITY_KEYS and stability["dof"] == 2 and len(stability["windows"]) == 3
    window = stability["windows"][0]
    assert set(window) == {"start", "end", "count", "estimate", "std", "covariance"} and set(window["estimate"]) == {"bias"}
    assert [w["start"] < w["end"] for w in stability["windows"]] == [True] * 3
    assert sum(line.startswith("stability: ") for line in result.stdout.splitlines()) == 1
    # the console wraps long lines: compare with the whitespace collapsed
    assert f"stability: {' '.join(stability['sentence'].split())}" in " ".join(result.stdout.split())


def test_scale_bias_summary_and_terminal_line(logs, tmp_path):
    result = _invoke("calibrate", "scale-bias", "--data", logs / "sb" / "data.csv", "--out", tmp_path)
    assert result.exit_code == 0, result.output
    stability = json.loads((tmp_path / "summary.json").read_text())["stability"]
    assert stability["parameters"] == ["theta1", "theta2"] and stability["dof"] == 2 and stability["model"] == "constant"
    assert sum(line.startswith("stability: ") for line in result.stdout.splitlines()) == 1


@pytest.mark.parametrize("value", ["0", "-2"])
def test_bad_windows_are_one_line_exit_2(logs, tmp_path, value):
    result = _invoke("calibrate", "scale-bias", "--data", logs / "sb" / "data.csv", "--windows", value, "--out", tmp_path / "c")
    assert result.exit_code == 2
    assert result.stderr.strip().count("\n") == 0 and "--windows: expected a whole number" in result.stderr


def test_the_api_takes_windows(logs):
    result = kalcal.calibrate("accel-gps", logs / "ag" / "imu.csv", logs / "ag" / "gps.csv", windows=4)
    assert result.stability["dof"] == 3 and result.to_dict()["stability"]["dof"] == 3
    off = kalcal.calibrate("scale-bias", data=logs / "sb" / "data.csv", windows=1)
    assert off.stability["stable"] is None and off.stability["sentence"] == "not tested: one window (--windows 1)"
