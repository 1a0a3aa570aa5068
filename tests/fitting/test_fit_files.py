"""What a fit writes into filter.toml: a [scenario] that verify runs as it is, the latency the likelihood
used, a truth without the log's faults, and the gate a calibration must repeat."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest
from typer.testing import CliRunner

import kalcal
from kalcal.cli import app
from kalcal.jobs.verify_arguments import MAX_UPDATES, check_arguments, default_long_run
from kalcal.models.registry import build_scenario

ROVER = Path(__file__).resolve().parents[2] / "examples" / "rover-like.toml"


def _invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)


def _rover_logs(tmp_path, seed, duration, **truth):
    settings = {"scenario.duration": duration, **{f"truth.{key}": value for key, value in truth.items()}}
    paths = kalcal.simulate("accel-gps", seed=seed, config=ROVER, settings=settings).save(tmp_path / "sim")
    return paths["imu"], paths["gps"]


@pytest.fixture(scope="module")
def rover_fit(tmp_path_factory):
    """A fit of a 10 s, 20 Hz rover-like log with the rover-like config (300 s): its folder."""
    base = tmp_path_factory.mktemp("rover-fit")
    imu, gps = _rover_logs(base, 3, 10)
    fitted = _invoke("fit", "accel-gps", "--imu", imu, "--gps", gps, "--config", ROVER, "--out", base / "fit")
    assert fitted.exit_code == 0, fitted.stdout + fitted.stderr
    return base / "fit"


def test_a_20_hz_rover_like_fit_writes_a_scenario_within_verifys_limits(rover_fit):
    out = rover_fit
    text = (out / "filter.toml").read_text()
    scenario = tomllib.loads(text)["scenario"]
    # the rover-like config's 300 s at 20 Hz are 6000 fixes: shortened to the most verify allows, and said
    assert scenario["gps_rate"] == 20.0 and scenario["duration"] * scenario["gps_rate"] == MAX_UPDATES
    assert "# duration: the scenario's 300 s shortened to 100 s" in text
    built = build_scenario("accel-gps", out / "filter.toml", [])
    assert default_long_run(built) == MAX_UPDATES / 20.0  # 120 s would be 2400 fixes
    check_arguments(built, 2000)  # the run and its default long run (skipped: not longer than the run) fit


@pytest.mark.slow
def test_verify_runs_a_20_hz_rover_like_fits_filter_toml_without_overrides(rover_fit, tmp_path):
    """The loop closed as docs/fit.md gives it: about 3 minutes (2000 realizations of 2000 fixes)."""
    verified = _invoke("verify", "--config", rover_fit / "filter.toml", "-n", 2000, "--no-report", "--out", tmp_path / "ver")
    assert verified.exit_code == 0, verified.stdout + verified.stderr


def test_the_default_long_run_of_a_short_20_hz_run_is_the_most_a_realization_holds():
    scenario = build_scenario("accel-gps", None, ["scenario.gps_rate=20", "scenario.duration=10"])
    assert default_long_run(scenario) == 100.0
    check_arguments(scenario, 100)
    assert default_long_run(build_scenario("accel-gps", None, [])) == 120.0  # 600 fixes at 5 Hz: unchanged


def test_filter_toml_writes_the_latency_the_fit_used_and_a_truth_without_the_logs_faults(tmp_path):
    imu, gps = _rover_logs(tmp_path, 4, 10, gps_latency=0.02, gps_outlier_rate=0.01, gps_outlier_std=30.0)
    assignments = {"truth.gps_latency": 0.02, "truth.gps_outlier_rate": 0.01, "truth.gps_outlier_std": 30.0}
    result = kalcal.fit("accel-gps", imu=imu, gps=gps, config=ROVER, settings=assignments,
                        free="filter.gps_position_std", out=tmp_path / "fit")
    written = tomllib.loads((tmp_path / "fit" / "filter.toml").read_text())
    # the likelihood took an unset filter.gps_latency as 0, not the truth's 0.02
    assert written["filter"]["gps_latency"] == 0.0
    assert {key: written["truth"][key] for key in ("gps_latency", "gps_outlier_rate", "gps_outlier_std")} == {
        "gps_latency": 0.0, "gps_outlier_rate": 0.0, "gps_outlier_std": 0.0}
    assert result.settings == written
