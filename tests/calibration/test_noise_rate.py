"""Noise settings at the wrong rate: a static log's noise identified at 100 Hz, used on a 200 Hz flight log.

A per-sample std holds at one rate only: N sqrt(f) for the white noise (m/s^2 from N in m/s^2/sqrt(Hz)),
K / sqrt(f) for the bias walk's step. ``kalcal noise`` writes the rate-free densities and ``calibrate``
converts them at each log's own rate; per-sample settings are applied as they stand, with a warning
where the rate they were written for is another (recorded in the file) or cannot be known.
"""

from __future__ import annotations

import json
import tomllib

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from kalcal.cli import app
from kalcal.scenarios import build_scenario

STATIC_RATE, FLIGHT_RATE = 100.0, 200.0
DENSITY = 2e-3  # N, m/s^2/sqrt(Hz): 0.02 m/s^2 per sample at 100 Hz, 0.0283 at 200 Hz


def _invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """The 100 Hz static log's ``kalcal noise`` folder and a 30 s, 200 Hz flight log of the same sensor."""
    base = tmp_path_factory.mktemp("rates")
    rng = np.random.default_rng(11)
    n = int(120 * STATIC_RATE) + 1
    accel = 9.81 + 0.05 + DENSITY * np.sqrt(STATIC_RATE) * rng.standard_normal(n)
    pd.DataFrame({"time": np.arange(n) / STATIC_RATE, "accel": accel}).to_csv(base / "static.csv", index=False)
    noise = base / "noise"
    assert _invoke("noise", "--imu", base / "static.csv", "--out", noise).exit_code == 0
    sim = base / "sim"
    per_sample = float(DENSITY * np.sqrt(FLIGHT_RATE))
    done = _invoke("simulate", "accel-gps", "--seed", "3", "--out", sim, "--set", f"truth.accel_noise_std={per_sample!r}")
    assert done.exit_code == 0, done.output
    return noise, sim


def _calibrate(sim, out, *args):
    result = _invoke("calibrate", "accel-gps", "--imu", sim / "imu.csv", "--gps", sim / "gps.csv", "--out", out, *args)
    assert result.exit_code == 0, result.output
    return json.loads((out / "summary.json").read_text())


def _bias_sigma(summary) -> float:
    return float(summary["bias_std"])


def test_noise_file_from_100_hz_gives_the_200_hz_log_its_own_per_sample_noise(logs, tmp_path):
    """The issue's case: on the code before the densities the file's per-sample 0.0198 was applied at
    200 Hz, a bias sigma about 0.71x the one of the same noise at the log's rate; now the same sigma."""
    noise, sim = logs
    summary = json.loads((noise / "summary.json").read_text())
    density = summary["velocity_random_walk"]["value"]  # N as identified, m/s^2/sqrt(Hz)
    assert summary["velocity_random_walk"]["ci_low"] <= DENSITY <= summary["velocity_random_walk"]["ci_high"]
    with_file = _calibrate(sim, tmp_path / "file", "--config", noise / "filter.toml")
    # the same noise given per sample at the flight log's rate, the key the code before the densities had too
    at_rate = float(float(f"{density:.6g}") * np.sqrt(FLIGHT_RATE))
    reference = _calibrate(sim, tmp_path / "ref", "--set", f"filter.accel_noise_std={at_rate!r}")
    ratio = _bias_sigma(with_file) / _bias_sigma(reference)
    print(f"bias sigma with the 100 Hz noise file / with the noise at 200 Hz: {ratio:.6f}")
    assert ratio == pytest.approx(1.0, rel=1e-6)
    # ... against the per-sample value at 100 Hz applied at 200 Hz, what the file held before the densities:
    # a sigma between sqrt(100 / 200) = 0.707 (the accelerometer noise alone) and 1 (the GPS noise alone)
    # times the right one; 0.856 on this log
    stale = _calibrate(sim, tmp_path / "stale", "--set", f"filter.accel_noise_std={float(f'{density:.6g}') * 10.0!r}")
    stale_ratio = _bias_sigma(stale) / _bias_sigma(reference)
    print(f"bias sigma with the per-sample value at 100 Hz / with the noise at 200 Hz: {stale_ratio:.4f}")
    assert np.sqrt(0.5) < stale_ratio < 0.95
    assert not [w for w in with_file["warnings"] if w["code"].startswith("noise-rate")]


def test_an_old_noise_file_warns_that_its_rate_cannot_be_checked(logs, tmp_path):
    """A filter.toml written before the densities: per-sample values, the rate in a comment only."""
    _, sim = logs
    old = tmp_path / "old.toml"
    old.write_text("# kalcal noise: ... Per-sample values hold at 100 Hz;\n\n[filter]\naccel_noise_std = 0.02\n")
    summary = _calibrate(sim, tmp_path / "cal", "--config", old)
    codes = [w for w in summary["warnings"] if w["code"] == "noise-rate-unknown"]
    assert len(codes) == 1 and "filter.accel_noise_std" in codes[0]["message"] and str(old) in codes[0]["message"]
    assert "filter.accel_noise_density" in codes[0]["message"] and "200 Hz" in codes[0]["message"]


def test_a_per_sample_setting_written_for_another_rate_warns_naming_both(logs, tmp_path):
    """A fit's filter.toml from before the densities records its log's rate in [scenario] imu_rate."""
    _, sim = logs
    old = tmp_path / "fit.toml"
    old.write_text("[scenario]\nimu_rate = 100.0\ngps_rate = 5.0\n\n[filter]\naccel_noise_std = 0.02\nbias_walk_std = 1e-4\n")
    summary = _calibrate(sim, tmp_path / "cal", "--config", old)
    found = {w["message"].split(": ")[1].split(" =")[0]: w for w in summary["warnings"] if w["code"] == "noise-rate-mismatch"}
    assert set(found) == {"filter.accel_noise_std", "filter.bias_walk_std"}
    white = found["filter.accel_noise_std"]["message"]
    assert "written for 100 Hz" in white and "at 200 Hz" in white and "0.707 times" in white
    assert "filter.accel_noise_density = 0.002 m/s^2/sqrt(Hz)" in white
    walk = found["filter.bias_walk_std"]["message"]
    assert "1.41 times" in walk and "filter.bias_walk_density = 0.001 m/s^3/sqrt(Hz)" in walk
    # a file written at the log's own rate: nothing to warn of
    own = tmp_path / "own.toml"
    own.write_text(old.read_text().replace("imu_rate = 100.0", "imu_rate = 200.0"))
    assert not [w for w in _calibrate(sim, tmp_path / "same", "--config", own)["warnings"] if w["code"].startswith("noise-rate")]
    # the file's rate replaced on the command line: the file still says its values were written for 100 Hz
    # (they were called "unknown", the message claiming "its file gives no scenario.imu_rate")
    over = _calibrate(sim, tmp_path / "over", "--config", old, "--set", "scenario.imu_rate=200")["warnings"]
    rated = [w for w in over if w["code"].startswith("noise-rate")]
    assert sorted(w["code"] for w in rated) == ["noise-rate-mismatch"] * 2
    assert all("written for 100 Hz" in w["message"] and "at 200 Hz" in w["message"] for w in rated)
    assert not any("gives no scenario.imu_rate" in w["message"] for w in over)


def test_a_rate_on_the_command_line_is_not_an_old_files_rate(logs, tmp_path):
    """An old noise file (its rate in a comment only) with ``--set scenario.imu_rate=200``: the command
    line's rate says nothing about the rate the file's value was written for, so the warning stays."""
    _, sim = logs
    old = tmp_path / "old.toml"
    old.write_text("# kalcal noise: ... Per-sample values hold at 100 Hz;\n\n[filter]\naccel_noise_std = 0.02\n")
    summary = _calibrate(sim, tmp_path / "cal", "--config", old, "--set", "scenario.imu_rate=200")
    assert [w["code"] for w in summary["warnings"] if w["code"].startswith("noise-rate")] == ["noise-rate-unknown"]
    # a value given on the command line with its rate is the command line's own: no warning
    both = _calibrate(sim, tmp_path / "set", "--set", "filter.accel_noise_std=0.02", "--set", "scenario.imu_rate=200")
    assert not [w for w in both["warnings"] if w["code"].startswith("noise-rate")]


def test_the_built_in_noise_is_a_density_at_the_default_rate(tmp_path):
    """The built-in noise is one density, 0.02 m/s^2 per sample at 200 Hz, everywhere: a log at another
    rate gets 0.02 sqrt(rate / 200) per sample; within 1% of scenario.imu_rate the truth's value there is
    kept; simulate and verify at another scenario.imu_rate draw the same density (the truth was 0.02 per
    sample at 100 Hz while calibrate assumed 0.0141: a bias sigma 0.86x the right one, silently); a value
    given (filter or truth) stays as given."""
    scenario = build_scenario("accel-gps")
    assert scenario.truth.accel_noise_std == 0.02  # 200 Hz, unchanged
    assert scenario.at_rate(100.0).filter_settings.accel_noise_std == pytest.approx(0.02 * np.sqrt(0.5), rel=1e-12)
    assert scenario.at_rate(400.0).filter_settings.accel_noise_std == pytest.approx(0.02 * np.sqrt(2.0), rel=1e-12)
    assert scenario.at_rate(201.0).filter_settings.accel_noise_std == 0.02
    at_100 = build_scenario("accel-gps", assignments=["scenario.imu_rate=100"])
    assert at_100.truth.accel_noise_std == pytest.approx(0.02 * np.sqrt(0.5), rel=1e-12)  # what simulate draws
    assert at_100.at_rate(100.0).filter_settings.accel_noise_std == at_100.truth.accel_noise_std
    assert at_100.at_rate(200.0).filter_settings.accel_noise_std == pytest.approx(0.02, rel=1e-12)
    for key in ("filter.accel_noise_std", "truth.accel_noise_std"):
        given = build_scenario("accel-gps", assignments=[f"{key}=0.03"])
        assert given.at_rate(100.0).filter_settings.accel_noise_std == 0.03
    # a log simulated at 100 Hz with the defaults, calibrated with the defaults: the sigma of its true noise
    sim = tmp_path / "sim"
    assert _invoke("simulate", "accel-gps", "--seed", "4", "--out", sim, "--set", "scenario.imu_rate=100").exit_code == 0
    default = _calibrate(sim, tmp_path / "default")
    true = at_100.truth.accel_noise_std
    with_truth = _calibrate(sim, tmp_path / "set", "--set", f"filter.accel_noise_std={true!r}")
    assert _bias_sigma(default) == pytest.approx(_bias_sigma(with_truth), rel=1e-9)
    stale = _calibrate(sim, tmp_path / "stale", "--set", "filter.accel_noise_std=0.02")
    assert _bias_sigma(stale) > 1.01 * _bias_sigma(default)


def test_density_converts_at_the_rate_it_runs_at():
    """verify converts at scenario.imu_rate; a log at its own rate (at_rate)."""
    scenario = build_scenario("accel-gps", assignments=["filter.accel_noise_density=0.002", "truth.bias_walk_density=1e-3",
                                                        "scenario.imu_rate=100"])
    assert scenario.filter_settings.accel_noise_std == pytest.approx(0.02, rel=1e-12)
    assert scenario.truth.bias_walk_std == pytest.approx(1e-4, rel=1e-12)
    assert scenario.filter_settings.bias_walk_std == pytest.approx(1e-4, rel=1e-12)  # the truth's, unset in the filter
    at_200 = scenario.at_rate(200.0).filter_settings
    assert at_200.accel_noise_std == pytest.approx(0.002 * np.sqrt(200), rel=1e-12)
    assert at_200.bias_walk_std == pytest.approx(1e-3 / np.sqrt(200), rel=1e-12)


@pytest.mark.parametrize("section", ["filter", "truth"])
def test_a_per_sample_value_and_its_density_together_are_refused(section, tmp_path):
    path = tmp_path / "both.toml"
    path.write_text(f"[{section}]\naccel_noise_std = 0.02\naccel_noise_density = 0.002\n")
    result = _invoke("calibrate", "accel-gps", "--imu", "x.csv", "--gps", "y.csv", "--config", path)
    assert result.exit_code == 2
    line = result.output.strip()
    assert line.count("\n") == 0 and f"{section}.accel_noise_density" in line and "not both" in line
