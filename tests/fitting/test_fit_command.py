"""``kalcal fit``: bad input as one line with exit 2, fit.json's fields, filter.toml through --config of
calibrate and verify (the loop closed), and the set of files."""

from __future__ import annotations

import json
import struct
import tomllib

import pytest
from typer.testing import CliRunner

import kalcal
from kalcal.cli import app


def _invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture(scope="module")
def accel_logs(tmp_path_factory):
    base = tmp_path_factory.mktemp("fit-logs")
    sim = kalcal.simulate("accel-gps", seed=2, settings={"scenario.duration": 10, "truth.gps_position_std": 2.0})
    sim.save(base)
    return base / "imu.csv", base / "gps.csv"


@pytest.fixture(scope="module")
def accel_fit(accel_logs, tmp_path_factory):
    out = tmp_path_factory.mktemp("fit") / "out"
    imu, gps = accel_logs
    result = _invoke("fit", "accel-gps", "--imu", imu, "--gps", gps, "--out", out,
                     "--free", "filter.gps_position_std,filter.gps_velocity_std")
    assert result.exit_code == 0, result.stdout + result.stderr
    return out, result


@pytest.mark.parametrize(
    "args, start",
    [
        (["--imu", "missing.csv", "--gps", "{gps}"], "kalcal: error: missing.csv"),
        (["--imu", "{imu}", "--gps", "{gps}", "--free", "filter.accel_amplitude"], "kalcal: error: --free: "),
        (["--imu", "{imu}", "--gps", "{gps}", "--free", "log.position_std_multiplier"], "kalcal: error: --free: "),
        (["--imu", "{imu}", "--gps", "{gps}", "--gate", "1.5"], "kalcal: error: --gate: expected a confidence"),
        (["--imu", "{imu}"], "kalcal: error: --gps: required"),
        (["--imu", "{imu}", "--gps", "{gps}", "--set", "filter.accel_noise_std=-1"], "kalcal: error: filter.accel_noise_std"),
    ],
)
def test_bad_input_is_one_line_and_exit_status_2_as_in_calibrate(accel_logs, tmp_path, args, start):
    imu, gps = accel_logs
    args = [a.format(imu=imu, gps=gps) for a in args]
    result = _invoke("fit", "accel-gps", *args, "--out", tmp_path / "out")
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(start), result.stderr
    assert not (tmp_path / "out" / "fit.json").exists()


def test_scale_bias_refuses_what_it_does_not_use(tmp_path):
    for args, start in ((["--gate", "0.99", "--data", "x.csv"], "kalcal: error: --gate: "), ([], "kalcal: error: --data: required")):
        result = _invoke("fit", "scale-bias", *args, "--out", tmp_path / "out")
        assert result.exit_code == 2 and result.stderr.strip().startswith(start), result.stderr


def test_fit_json_holds_the_issue_s_fields(accel_fit):
    out, result = accel_fit
    document = json.loads((out / "fit.json").read_text())
    assert document["schema_version"] >= 1 and document["scenario"] == "accel-gps"
    for key in ("loglik", "aic", "fixes", "converged", "adequate", "adequacy", "diagnostics", "interval_method"):
        assert key in document, key
    assert document["interval_method"] == "observed-information"
    assert document["aic"] == pytest.approx(2 * 2 - 2 * document["loglik"])
    position = document["parameters"]["filter.gps_position_std"]
    assert set(position) >= {"value", "ci_low", "ci_high", "unit", "identified", "at_bound"}
    assert position["unit"] == "m" and position["ci_low"] <= 2.0 <= position["ci_high"]
    assert "filter.gps_position_std" in result.stdout and "wrote" in result.stdout
    manifest = json.loads((out / ".kalcal-manifest.json").read_text())
    assert manifest["command"] == "fit accel-gps" and manifest["complete"]
    width, height = struct.unpack(">II", (out / "fit.png").read_bytes()[16:24])
    assert (width, height) == (900, 400)  # one row of two panels


def test_filter_toml_goes_through_config_of_calibrate_and_verify_with_the_fitted_values(accel_fit, accel_logs):
    out, _ = accel_fit
    imu, gps = accel_logs
    text = (out / "filter.toml").read_text()
    config = tomllib.loads(text)
    fitted = json.loads((out / "fit.json").read_text())["parameters"]["filter.gps_position_std"]["value"]
    assert config["filter"]["gps_position_std"] == pytest.approx(fitted, rel=1e-5)
    assert config["truth"]["gps_position_std"] == config["filter"]["gps_position_std"]
    assert config["scenario"]["imu_rate"] == 200.0 and config["scenario"]["gps_rate"] == 5.0
    assert "# gps_position_std: fitted, interval [" in text
    calibration = kalcal.calibrate("accel-gps", imu=imu, gps=gps, config=out / "filter.toml")
    settings = calibration.summary["settings"]
    assert settings["filter"]["gps_position_std"] == config["filter"]["gps_position_std"]
    # the loop closed: the fitted filter verified by Monte Carlo against the fitted settings as the truth
    verification = kalcal.verify("accel-gps", config=out / "filter.toml", n=1000, seed=1, long_run=0,
                                 settings={"scenario.duration": 10})
    assert verification.verdict == "pass"
    assert verification.to_dict()["settings"]["truth"]["gps_position_std"] == config["truth"]["gps_position_std"]


def test_scale_bias_end_to_end_fit_calibrate_and_verify(tmp_path):
    sim = kalcal.simulate("scale-bias", seed=4, settings={"scenario.duration": 60, "truth.reference_noise_std": 0.3})
    sim.save(tmp_path / "sim")
    out = tmp_path / "fit"
    result = _invoke("fit", "scale-bias", "--data", tmp_path / "sim" / "data.csv", "--out", out, "--profile")
    assert result.exit_code == 0, result.stdout + result.stderr
    document = json.loads((out / "fit.json").read_text())
    assert document["interval_method"] == "profile" and document["scenario"] == "scale-bias"
    noise = document["parameters"]["filter.reference_noise_std"]
    assert noise["ci_low"] <= 0.3 <= noise["ci_high"]
    config = tomllib.loads((out / "filter.toml").read_text())
    assert config["filter"]["sensor_noise_std"] == 0.0 and config["scenario"]["rate"] == 10.0
    kalcal.calibrate("scale-bias", data=tmp_path / "sim" / "data.csv", config=out / "filter.toml")
    verification = kalcal.verify("scale-bias", config=out / "filter.toml", n=300, seed=0, long_run=0)
    assert verification.verdict == "pass"


def test_the_noise_is_fitted_and_written_as_densities_with_per_sample_values_at_the_logs_rate(accel_logs, tmp_path, monkeypatch):
    """[filter] and [truth] hold the densities only; the per-sample values at the log's 200 Hz are in
    comments, in fit.json's per_sample and on the terminal; imu.yaml holds the same densities."""
    import numpy as np

    imu, gps = accel_logs
    out = tmp_path / "fit"
    args = ["fit", "accel-gps", "--imu", imu, "--gps", gps, "--out", out, "--free", "filter.accel_noise_density,filter.gps_position_std"]
    # a terminal wide enough for the table's unit column (the console is made once per process, so an
    # earlier test's console of another width is replaced, not reread from COLUMNS)
    from rich.console import Console

    import kalcal.cli._common as common

    monkeypatch.setattr(common, "console", Console(width=200), raising=False)
    result = CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)
    assert result.exit_code == 0, result.stdout + result.stderr
    text = (out / "filter.toml").read_text()
    written = tomllib.loads(text)
    for section in ("filter", "truth"):
        assert {"accel_noise_density", "bias_walk_density"} <= set(written[section])
        assert not {"accel_noise_std", "bias_walk_std"} & set(written[section])
    document = json.loads((out / "fit.json").read_text())
    density = written["filter"]["accel_noise_density"]
    per_sample = document["per_sample"]
    assert per_sample["rate"] == pytest.approx(200.0)
    assert per_sample["accel_noise_std"]["value"] == pytest.approx(density * np.sqrt(200.0), rel=1e-12)
    p = document["parameters"]["filter.accel_noise_density"]
    assert per_sample["accel_noise_std"]["ci_high"] == pytest.approx(p["ci_high"] * np.sqrt(200.0), rel=1e-12)
    assert f"accel_noise_std = {density * np.sqrt(200.0):.6g} m/s^2 per sample at 200 Hz" in text
    assert "m/s^2 per sample at 200 Hz" in result.stdout and "= accel_noise_std" in result.stdout
    yaml = (out / "imu.yaml").read_text()
    assert f"accelerometer_noise_density: {density:.6g}  # m/s^2/sqrt(Hz)\n" in yaml and "update_rate: 200  # Hz" in yaml
    # calibrate on the log at its own rate: the densities give back the per-sample value the fit ran
    cal = tmp_path / "cal"
    done = _invoke("calibrate", "accel-gps", "--imu", imu, "--gps", gps, "--config", out / "filter.toml", "--out", cal)
    assert done.exit_code == 0, done.stdout + done.stderr
    summary = json.loads((cal / "summary.json").read_text())
    assert not [w for w in summary["warnings"] if w["code"].startswith("noise-rate")]
    from kalcal.scenarios import build_scenario

    scenario = build_scenario("accel-gps", out / "filter.toml")
    assert scenario.filter_settings.accel_noise_std == pytest.approx(per_sample["accel_noise_std"]["value"], rel=1e-6)


def test_the_per_sample_row_comes_from_the_fit_not_the_cli():
    """The CLI prints under a fitted setting what the fit derived from it (FitResult.derived): the
    density's per-sample std at the log's rate, its interval mapped, its unit naming the rate; the CLI
    itself maps no scenario's settings to other names or units (its options' help texts aside)."""
    from pathlib import Path

    import kalcal.cli.fit as cli_fit
    from kalcal.fitting.result import FitParameter
    from kalcal.scenarios.accel_gps.fit import per_sample_parameters

    source = Path(cli_fit.__file__).read_text(encoding="utf-8")
    assert '"filter.accel_noise_density":' not in source and "per sample" not in source
    density = FitParameter("filter.accel_noise_density", 0.002, 0.0015, 0.003, "m/s^2/sqrt(Hz)", 0.001)
    per_sample = {"rate": 400.0, "accel_noise_std": {"value": 0.04, "ci_low": 0.03, "ci_high": 0.06},
                  "bias_walk_std": {"value": 0.0, "ci_low": None, "ci_high": None}}
    derived = per_sample_parameters({density.name: density}, per_sample)
    assert set(derived) == {"filter.accel_noise_density"}  # only the settings fitted
    shown = derived["filter.accel_noise_density"]
    assert (shown.name, shown.value, shown.ci_low, shown.ci_high) == ("accel_noise_std", 0.04, 0.03, 0.06)
    assert shown.unit == "m/s^2 per sample at 400 Hz" and shown.identified
