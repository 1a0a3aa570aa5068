"""``kalcal noise``: files written, the filter.toml round trip through ``calibrate --config``, and bad input
as one line with exit status 2."""

from __future__ import annotations

import dataclasses
import json
import re
import struct
import tomllib

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from kalcal.cli import app
from kalcal.scenarios.accel_gps.settings import AccelGpsFilter

RATE = 200.0
NOISE_STD = 0.02  # m/s^2 per sample
WALK = 2e-3  # K, m/s^2/sqrt(s)
PARAMETERS = ("accel_noise_std", "velocity_random_walk", "bias_instability", "rate_random_walk")
UNITS = {
    "accel_noise_std": "m/s^2",
    "velocity_random_walk": "m/s/sqrt(s)",
    "bias_instability": "m/s^2",
    "rate_random_walk": "m/s^2/sqrt(s)",
}


def _invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)


def _static(seed: int, duration: float, walk: float = 0.0, rate: float = RATE) -> pd.DataFrame:
    """A static log: gravity + bias + a bias random walk of K = ``walk`` + white noise of NOISE_STD."""
    rng = np.random.default_rng(seed)
    n = int(round(duration * rate)) + 1
    accel = 9.81 + 0.05 + NOISE_STD * rng.standard_normal(n)
    if walk:
        accel += np.cumsum(walk / np.sqrt(rate) * rng.standard_normal(n))
    return pd.DataFrame({"time": 100.0 + np.arange(n) / rate, "accel": accel})


@pytest.fixture(scope="module")
def drifting(tmp_path_factory):
    """(out dir, result) of ``kalcal noise`` on a 600 s Parquet log with renamed columns and a bias walk."""
    base = tmp_path_factory.mktemp("noise")
    _static(5, 600.0, WALK).rename(columns={"time": "t", "accel": "ax"}).to_parquet(base / "static.parquet")
    out = base / "out"
    result = _invoke("noise", "--imu", base / "static.parquet", "--out", out, "--imu-columns", "time=t,accel=ax")
    assert result.exit_code == 0, result.stdout + result.stderr
    return out, result


@pytest.fixture(scope="module")
def white(tmp_path_factory):
    """(out dir, result) of ``kalcal noise`` on a 60 s CSV log of white noise only."""
    base = tmp_path_factory.mktemp("noise-white")
    _static(6, 60.0).to_csv(base / "static.csv", index=False)
    out = base / "out"
    result = _invoke("noise", "--imu", base / "static.csv", "--out", out)
    assert result.exit_code == 0, result.stdout + result.stderr
    return out, result


def _png_size(path) -> tuple[int, int]:
    header = path.read_bytes()[:24]
    assert header[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", header[16:24])


def test_writes_summary_curve_plot_and_filter_settings(drifting):
    out, result = drifting
    summary = json.loads((out / "summary.json").read_text())
    assert summary["rate"] == {"value": pytest.approx(RATE, rel=1e-9), "unit": "Hz", "note": "median sample rate"}
    assert summary["duration"] == {"value": pytest.approx(600.0, rel=1e-12), "unit": "s"}
    assert summary["samples"] == 120001 and summary["mean"]["value"] == pytest.approx(9.86, abs=0.1)
    for name in PARAMETERS:
        item = summary[name]
        assert item["identified"] and item["unit"] == UNITS[name]
        assert item["ci_low"] <= item["value"] <= item["ci_high"]
        assert item["confidence"] == 0.95
    # At 95% (the command's level) the known values lie inside their intervals for this seed; the
    # numeric tests hold them at 99.9% over several logs.
    assert summary["accel_noise_std"]["ci_low"] <= NOISE_STD <= summary["accel_noise_std"]["ci_high"]
    assert summary["rate_random_walk"]["ci_low"] <= WALK <= summary["rate_random_walk"]["ci_high"]
    assert summary["bias_walk_std"]["value"] == pytest.approx(summary["rate_random_walk"]["value"] / np.sqrt(RATE), rel=1e-9)
    assert summary["notes"] == []
    curve = pd.read_csv(out / "allan.csv")
    assert list(curve.columns[:4]) == ["tau", "adev", "adev_low", "adev_high"]
    np.testing.assert_allclose(curve["adev"], summary["allan"]["adev"], rtol=1e-12)
    assert _png_size(out / "allan.png") == (900, 550)
    # the table, the regions and where the files are
    for name in PARAMETERS:
        assert name in result.stdout
    # the closing line names the folder once and the files in it (the form every command closes with)
    assert "read off the curve:" in result.stdout and f"wrote {out}/: " in result.stdout
    assert "filter.toml" in result.stdout.strip().splitlines()[-1]


def test_filter_toml_holds_the_settings_calibrate_accepts(drifting, tmp_path):
    out, _ = drifting
    summary = json.loads((out / "summary.json").read_text())
    settings = tomllib.loads((out / "filter.toml").read_text())
    assert set(settings) == {"filter"}
    accepted = {f.name for f in dataclasses.fields(AccelGpsFilter)}
    # [filter] holds the rate-free densities only, N and K; their per-sample values at the log's rate
    # in comments and in summary.json
    identified = {"accel_noise_density": "velocity_random_walk", "bias_walk_density": "rate_random_walk"}
    per_sample = {"accel_noise_density": "accel_noise_std", "bias_walk_density": "bias_walk_std"}
    expected = {"accel_noise_density", "bias_walk_density"} & accepted
    assert set(settings["filter"]) == expected == {"accel_noise_density", "bias_walk_density"}
    text = (out / "filter.toml").read_text()
    for key in expected:
        assert settings["filter"][key] == pytest.approx(summary[identified[key]]["value"], rel=1e-5)
        assert summary["filter"][key] == settings["filter"][key]
        name = per_sample[key]
        assert summary["per_sample"][name] == pytest.approx(summary[name]["value"], rel=1e-5)
        assert f"# {key}: {name} = {summary[name]['value']:.6g} m/s^2 per sample at 200 Hz" in text
    assert summary["per_sample"]["rate"] == pytest.approx(RATE)

    # Round trip: a short simulated flight calibrated with the identified settings.
    sim = tmp_path / "sim"
    assert _invoke("simulate", "accel-gps", "--seed", "4", "--out", sim, "--set", "scenario.duration=4").exit_code == 0
    cal = tmp_path / "cal"
    result = _invoke(
        "calibrate", "accel-gps", "--imu", sim / "imu.csv", "--gps", sim / "gps.csv", "--out", cal,
        "--config", out / "filter.toml",
    )
    assert result.exit_code == 0, result.stdout + result.stderr
    cal_summary = json.loads((cal / "summary.json").read_text())
    used = cal_summary["settings"]["filter"]
    for key in expected:
        assert used[key] == settings["filter"][key]
    # densities carry their own rate: nothing about the noise's rate to warn of
    assert not [w for w in cal_summary["warnings"] if w["code"].startswith("noise-rate")]


def test_white_noise_log_reports_what_it_cannot_see(white):
    out, result = white
    summary = json.loads((out / "summary.json").read_text())
    assert summary["accel_noise_std"]["ci_low"] <= NOISE_STD <= summary["accel_noise_std"]["ci_high"]
    for name in ("bias_instability", "rate_random_walk"):
        item = summary[name]
        assert not item["identified"] and item["value"] is None and item["upper_bound"] > 0
        assert "too short a log" in item["note"]
    assert len(summary["notes"]) == 2
    settings = tomllib.loads((out / "filter.toml").read_text())
    assert set(settings["filter"]) == {"accel_noise_density"}
    assert "# bias_walk_density: not written" in (out / "filter.toml").read_text()
    assert "not seen" in result.stdout and "note: rate_random_walk: not identified" in result.stdout


def test_same_log_same_bytes(white, tmp_path):
    out, _ = white
    again = tmp_path / "again"
    assert _invoke("noise", "--imu", out.parent / "static.csv", "--out", again).exit_code == 0
    for name in ("allan.png", "allan.csv", "filter.toml"):
        assert (again / name).read_bytes() == (out / name).read_bytes(), name


def _uneven(frame):
    frame = frame.copy()
    frame.loc[300:, "time"] += 0.5 / RATE  # one step of 1.5 periods, ending at data row 301
    return frame


def _cell(row, column, value):
    def change(frame):
        frame = frame.astype({column: object})
        frame.loc[row, column] = value
        return frame

    return change


BAD_LOGS = {
    "missing column": (lambda f: f.rename(columns={"accel": "acc"}), r"missing column 'accel'"),
    "text cell": (_cell(10, "accel", "oops"), r"row 11, column 'accel': not a number: 'oops'"),
    "NaN": (_cell(7, "accel", float("nan")), r"row 8, column 'accel': value is nan"),
    "infinite": (_cell(7, "accel", float("inf")), r"row 8, column 'accel': value is inf"),
    "time goes back": (_cell(20, "time", 0.0), r"row 21, column 'time': time 0 does not increase"),
    "uneven steps": (_uneven, r"row 301, column 'time': step 0.0075 s differs from the median step 0.005 s by 50%"),
    "too short": (lambda f: f.iloc[:20], r"column 'accel': 20 samples are too few for an Allan deviation"),
    "constant": (lambda f: f.assign(accel=9.81), r"reads 9.81 m/s\^2 throughout"),
}


@pytest.mark.parametrize("case", list(BAD_LOGS))
def test_bad_log_is_one_line_and_exit_status_2(case, tmp_path):
    change, pattern = BAD_LOGS[case]
    path = tmp_path / "bad_static.csv"
    change(_static(7, 2.0)).to_csv(path, index=False)
    _assert_refused(tmp_path, pattern, "--imu", path)


@pytest.mark.parametrize(
    ("args", "pattern"),
    [
        (("--imu", "nowhere.csv"), r"nowhere.csv: no such file"),
        (("--imu", "log.txt"), r"unknown file type '.txt'"),
        ((), r"--imu: required"),
        (("--imu", "{log}", "--imu-columns", "speed=v"), r"--imu-columns: unknown role 'speed'"),
    ],
)
def test_bad_arguments_are_one_line_and_exit_status_2(args, pattern, tmp_path):
    log = tmp_path / "static.csv"
    _static(8, 2.0).to_csv(log, index=False)
    _assert_refused(tmp_path, pattern, *(str(a).format(log=log) for a in args))


def _assert_refused(tmp_path, pattern, *args):
    out = tmp_path / "out"
    result = _invoke("noise", *args, "--out", out)
    assert result.exit_code == 2, (result.exit_code, result.stdout, result.stderr)
    message = result.stderr.rstrip("\n")
    assert "\n" not in message, f"not one line: {message!r}"
    assert message.startswith("kalcal: error: ")
    assert re.search(pattern, message), message
    assert "Traceback" not in result.stdout + result.stderr
    assert not out.exists()


def test_noise_closes_with_one_line_naming_what_it_wrote(white):
    out, result = white
    assert result.stdout.strip().splitlines()[-1] == f"wrote {out}/: summary.json, allan.csv, allan.png, filter.toml, imu.yaml"
