"""Simulated GNSS faults (latency, outliers): stamps shifted exactly, outliers at their rate and size, the
rest of the log unchanged; verify refuses them; the rover-like example simulates and calibrates.

Rates and sizes are held to bounds from theory at 1e-3: the outlier count is binomial(N, rate) and the
gross errors over their std are N(0, 1), so their sum of squares is chi-square(count).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats
from typer.testing import CliRunner

import kalcal
from kalcal.cli import app
from kalcal.errors import ConfigError
from kalcal.scenarios import build_scenario
from kalcal.scenarios.accel_gps.sampled import sample_accel_gps_logs

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "rover-like.toml"


def _invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)


def _logs(*assignments, seed=4, n=1):
    return sample_accel_gps_logs(build_scenario("accel-gps", assignments=list(assignments)), np.random.default_rng(seed), n)


def test_latency_shifts_the_stamps_by_exactly_the_latency_and_nothing_else():
    plain = kalcal.simulate("accel-gps", 9).logs
    late = kalcal.simulate("accel-gps", 9, {"truth.gps_latency": 0.02}).logs
    assert np.array_equal(late["gps"]["time"].to_numpy(), plain["gps"]["time"].to_numpy() + 0.02)
    for name in ("imu", "truth"):
        pd.testing.assert_frame_equal(late[name], plain[name])
    pd.testing.assert_frame_equal(late["gps"][["position", "velocity"]], plain["gps"][["position", "velocity"]])


def test_a_late_fix_describes_the_truth_at_its_stamp_minus_the_latency_and_the_last_is_skipped():
    latency = 0.02
    sim = kalcal.simulate("accel-gps", 5, {"truth.gps_latency": latency})
    gps, truth = sim.logs["gps"], sim.logs["truth"]
    rows = np.rint((gps["time"].to_numpy() - latency) * 200.0).astype(int)  # the 200 Hz samples described
    for column, std in (("position", 1.0), ("velocity", 0.04)):
        squares = float(np.sum(((gps[column].to_numpy() - truth[column].to_numpy()[rows]) / std) ** 2))
        assert stats.chi2.ppf(0.0005, len(gps)) <= squares <= stats.chi2.ppf(0.9995, len(gps))
    summary = kalcal.calibrate("accel-gps", sim.logs["imu"], gps).to_dict()
    assert summary["fixes_skipped_outside"] == 1 and gps["time"].iloc[-1] > sim.logs["imu"]["time"].iloc[-1]


def test_zero_faults_change_nothing():
    plain, zero = _logs(), _logs("truth.gps_latency=0", "truth.gps_outlier_rate=0", "truth.gps_outlier_std=30")
    assert zero.gps_outlier_error is None and not zero.gps_outlier.any()
    for name in ("accel", "gps_position", "gps_velocity", "bias"):
        assert np.array_equal(getattr(zero, name), getattr(plain, name))


def test_outliers_appear_at_their_rate_and_size_and_touch_only_positions():
    rate, size = 0.05, 30.0
    plain = _logs(seed=11, n=20)
    faulty = _logs(f"truth.gps_outlier_rate={rate}", f"truth.gps_outlier_std={size}", seed=11, n=20)
    for name in ("accel", "gps_velocity", "position"):  # drawn after everything else
        assert np.array_equal(getattr(faulty, name), getattr(plain, name))
    error = faulty.gps_position - plain.gps_position
    hit = faulty.gps_outlier
    np.testing.assert_allclose(error, faulty.gps_outlier_error, rtol=0, atol=1e-9)
    assert np.all(error[~hit] == 0)
    count, total = int(hit.sum()), hit.size
    assert stats.binom.ppf(0.0005, total, rate) <= count <= stats.binom.ppf(0.9995, total, rate)
    squares = float(np.sum((error[hit] / size) ** 2))
    assert stats.chi2.ppf(0.0005, count) <= squares <= stats.chi2.ppf(0.9995, count)


@pytest.mark.parametrize(
    "assignment, message",
    [
        ("truth.gps_outlier_rate=1.5", "truth.gps_outlier_rate: expected a share of the fixes from 0 to 1, got 1.5"),
        ("truth.gps_outlier_rate=-0.1", "truth.gps_outlier_rate: expected zero or a positive number"),
        ("truth.gps_outlier_std=-1", "truth.gps_outlier_std: expected zero or a positive number"),
    ],
)
def test_bad_fault_settings_are_one_line(assignment, message):
    with pytest.raises(ConfigError, match=message.replace(".", r"\.")):
        build_scenario("accel-gps", assignments=[assignment])


@pytest.mark.parametrize(
    "settings, key",
    [
        (["truth.gps_latency=0.02"], "truth.gps_latency"),
        (["truth.gps_outlier_rate=0.01", "truth.gps_outlier_std=30"], "truth.gps_outlier_rate"),
    ],
)
def test_verify_refuses_log_only_faults_in_one_line(settings, key, tmp_path):
    args = [arg for s in settings for arg in ("--set", s)]
    result = _invoke("verify", "accel-gps", "-n", "200", *args, "--out", tmp_path / "v")
    assert result.exit_code == 2
    line = result.stderr.strip()
    assert "\n" not in line and f"{key}: expected 0 in a verification" in line
    assert not (tmp_path / "v").exists()
    result = _invoke("analyze", "accel-gps", *args, "--out", tmp_path / "a")
    assert result.exit_code == 2 and f"{key}: expected 0 in a verification" in result.stderr.strip()


def test_the_rover_like_example_simulates_and_calibrates_as_documented(tmp_path):
    # the example as shipped, shortened to 60 s to keep the suite fast
    sim = tmp_path / "rover"
    result = _invoke("simulate", "accel-gps", "--config", EXAMPLE, "--set", "scenario.duration=60", "--seed", "1", "--out", sim)
    assert result.exit_code == 0, result.output
    gps, imu = pd.read_csv(sim / "gps.csv"), pd.read_csv(sim / "imu.csv")
    assert len(gps) == 60 * 20 and len(imu) == 60 * 200 + 1
    truth = pd.read_csv(sim / "truth.csv")
    at_fixes = truth.set_index("time").loc[gps["time"]]
    # metres of height noise and a few cm/s of velocity noise, as the file says (2 m, 0.05 m/s): white
    # Gaussian per fix, so each sample std of the 1200 fixes lies within z = 4.5 of its standard error
    # sigma / sqrt(2 n) of sigma (two-sided probability 7e-6 each)
    n = len(gps)
    for column, sigma in (("position", 2.0), ("velocity", 0.05)):
        std = np.std(gps[column].to_numpy() - at_fixes[column].to_numpy())
        assert abs(std - sigma) <= 4.5 * sigma / np.sqrt(2 * n), (column, std)

    default = _invoke("calibrate", "accel-gps", "--imu", sim / "imu.csv", "--gps", sim / "gps.csv", "--out", tmp_path / "cal")
    assert default.exit_code == 0, default.output
    summary = json.loads((tmp_path / "cal" / "summary.json").read_text())
    assert summary["diagnostics"]["consistent"] is False
    assert summary["stability"]["model"] == "constant" and summary["stability"]["stable"] is False
    assert "stability: NOT stable" in " ".join(default.stdout.split())

    matched = _invoke(
        "calibrate", "accel-gps", "--imu", sim / "imu.csv", "--gps", sim / "gps.csv", "--config", EXAMPLE,
        "--set", "scenario.duration=60", "--out", tmp_path / "cal2",
    )  # fmt: skip
    assert matched.exit_code == 0, matched.output
    summary = json.loads((tmp_path / "cal2" / "summary.json").read_text())
    assert summary["diagnostics"]["consistent"] is True
    assert summary["stability"]["model"] == "Gauss-Markov" and summary["stability"]["stable"] is True
