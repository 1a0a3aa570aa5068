"""What a fit writes into filter.toml: a [scenario] that verify runs as it is, the latency the likelihood
used, a truth without the log's faults, and the gate a calibration must repeat."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest
from typer.testing import CliRunner

import kalcal
from kalcal.cli import app
from kalcal.api.verification import MAX_UPDATES, check_arguments, default_long_run
from kalcal.scenarios import build_scenario

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
    """The loop closed as docs/fit.md gives it: 2000 realizations of 2000 fixes, one to three minutes."""
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


def test_a_gated_fits_filter_toml_says_to_calibrate_with_the_same_gate(tmp_path):
    sim = kalcal.simulate("accel-gps", seed=4, settings={"scenario.duration": 20, "truth.gps_outlier_rate": 0.02,
                                                         "truth.gps_outlier_std": 40.0})
    result = kalcal.fit("accel-gps", imu=sim.logs["imu"], gps=sim.logs["gps"], gate=0.999,
                        free="filter.gps_position_std", out=tmp_path / "fit")
    text = (tmp_path / "fit" / "filter.toml").read_text()
    rejected = len(result.rejected_fixes)
    assert rejected >= 1
    assert f"# fitted with --gate 0.999 ({rejected} fixes rejected): calibrate with the same --gate 0.999" in text
    ungated = kalcal.fit("accel-gps", imu=sim.logs["imu"], gps=sim.logs["gps"], free="filter.gps_position_std",
                         out=tmp_path / "plain")
    assert ungated.rejected_fixes is None and "--gate" not in (tmp_path / "plain" / "filter.toml").read_text()


@pytest.fixture(scope="module")
def short_logs(tmp_path_factory):
    paths = kalcal.simulate("accel-gps", seed=2, settings={"scenario.duration": 5}).save(tmp_path_factory.mktemp("short"))
    return paths["imu"], paths["gps"]


@pytest.mark.parametrize(
    "free, start",
    [
        ("filter.gps_position_std,filter.gps_position_std", "kalcal: error: --free: filter.gps_position_std given more than once"),
        (",", "kalcal: error: --free: expected KEY,KEY... with no empty key, got ','"),
        ("filter.gps_position_std,,filter.gps_velocity_std", "kalcal: error: --free: expected KEY,KEY... with no empty key"),
    ],
    ids=["twice", "comma", "empty-key"],
)
def test_a_free_set_with_a_key_twice_or_an_empty_key_is_one_line_and_exit_2(short_logs, tmp_path, free, start):
    imu, gps = short_logs
    result = _invoke("fit", "accel-gps", "--imu", imu, "--gps", gps, "--free", free, "--out", tmp_path / "out")
    lines = result.stderr.strip().splitlines()
    assert result.exit_code == 2 and len(lines) == 1 and lines[0].startswith(start), result.stderr
    assert not (tmp_path / "out").exists()


def test_a_bad_confidence_names_the_apis_argument_not_an_option_the_command_lacks(short_logs):
    imu, gps = short_logs
    with pytest.raises(kalcal.KalcalError, match=r"^confidence=: expected a number in \(0, 1\), got 1\.5"):
        kalcal.fit("accel-gps", imu=imu, gps=gps, confidence=1.5)
    with pytest.raises(kalcal.KalcalError, match=r"^--free: filter\.bias_std given more than once"):
        kalcal.fit("accel-gps", imu=imu, gps=gps, free=["filter.bias_std", "filter.bias_std"])


def test_the_figure_draws_a_negative_latency_on_a_linear_axis_and_a_noise_std_on_a_log_one():
    from kalcal.plots.fit import fit_figure

    curves = {
        "filter.gps_latency": {"value": [-0.05, -0.02, 0.0, 0.01, 0.04], "loglik": [-5.0, -1.0, 0.0, -0.5, -4.0]},
        "filter.gps_position_std": {"value": [0.5, 1.0, 2.0], "loglik": [-3.0, 0.0, -3.0]},
    }
    parameters = {
        "filter.gps_latency": {"value": 0.0, "ci_low": -0.03, "ci_high": 0.02, "unit": "s", "identified": True, "at_bound": False},
        "filter.gps_position_std": {"value": 1.0, "ci_low": 0.7, "ci_high": 1.5, "unit": "m", "identified": True, "at_bound": False},
    }
    figure = fit_figure(curves, parameters)
    latency, position = figure.axes[0], figure.axes[1]
    assert latency.get_xscale() == "linear" and position.get_xscale() == "log"
    line = latency.get_lines()[0]
    assert list(line.get_xdata()) == curves["filter.gps_latency"]["value"]  # every point, the negative ones too
    low, high = latency.get_xlim()
    assert low <= -0.05 and high >= 0.04
    band = latency.patches[0]  # axvspan: a Rectangle (matplotlib >= 3.9) or a Polygon
    left = band.get_x() if hasattr(band, "get_x") else float(min(band.get_xy()[:, 0]))
    assert left == pytest.approx(-0.03)  # the interval's own negative end, not the curve's


def test_the_figure_draws_a_setting_searched_on_a_linear_scale_on_a_linear_axis_all_positive_too():
    """A latency whose every value is positive goes on a linear axis when the job names it (it passes
    kalcal.scenarios.accel_gps.fit.LINEAR), on a log one when nothing says it was searched on a linear scale."""
    from kalcal.scenarios.accel_gps.fit import LINEAR
    from kalcal.plots.fit import fit_figure

    curves = {"filter.gps_latency": {"value": [0.01, 0.02, 0.04], "loglik": [-3.0, 0.0, -3.0]}}
    parameters = {"filter.gps_latency": {"value": 0.02, "ci_low": 0.015, "ci_high": 0.03, "unit": "s",
                                         "identified": True, "at_bound": False}}  # fmt: skip
    assert fit_figure(curves, parameters, linear=tuple(LINEAR)).axes[0].get_xscale() == "linear"
    assert fit_figure(curves, parameters).axes[0].get_xscale() == "log"


def test_a_100_hz_scale_bias_fit_writes_a_duration_within_verifys_limit(tmp_path):
    sim = kalcal.simulate("scale-bias", seed=5, settings={"scenario.duration": 10, "scenario.rate": 100})
    data = sim.logs["data"]
    result = kalcal.fit("scale-bias", data=data, settings={"scenario.rate": 100}, out=tmp_path / "fit")
    text = (tmp_path / "fit" / "filter.toml").read_text()
    scenario = tomllib.loads(text)["scenario"]
    # the scenario's default 30 s at the log's 100 Hz are 3000 samples, more than verify allows
    assert scenario["rate"] == 100.0 and round(scenario["duration"] * scenario["rate"]) == MAX_UPDATES
    assert "# duration: the scenario's 30 s shortened to 20 s" in text and result.settings["scenario"] == scenario
    check_arguments(build_scenario("scale-bias", tmp_path / "fit" / "filter.toml", []), 300)
