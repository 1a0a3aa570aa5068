"""``kalcal simulate/calibrate/verify scale-bias``: the files, the round trip, and one-line errors (exit 2)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from kalcal.cli import app

ESTIMATE_COLUMNS = ["time", "theta1", "theta2", "theta1_std", "theta2_std"]
SUMMARY_KEYS = {"theta", "theta_covariance", "scale_error", "scale_error_std", "bias", "bias_std", "samples_used"}


def _invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)


def _one_line_error(result, *fragments: str) -> None:
    assert result.exit_code == 2, result.output + result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("kalcal: error: "), result.stderr
    for fragment in fragments:
        assert fragment in lines[0], lines[0]


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim")
    result = _invoke("simulate", "scale-bias", "--seed", 7, "--out", out)
    assert result.exit_code == 0, result.output + result.stderr
    return out


def test_simulate_writes_data_and_truth(simulated):
    data = pd.read_csv(simulated / "data.csv")
    assert list(data.columns) == ["time", "reference", "sensor"] and len(data) == 300
    assert data["time"].iloc[0] == pytest.approx(0.1) and data["time"].iloc[-1] == pytest.approx(30.0)
    truth = json.loads((simulated / "truth.json").read_text())
    assert {"scale_error", "bias", "theta", "settings"} <= set(truth)
    assert truth["theta"][0] == pytest.approx(1 / (1 - truth["scale_error"]), rel=1e-12)
    assert truth["theta"][1] == pytest.approx(truth["bias"] / (1 - truth["scale_error"]), rel=1e-12)


def test_round_trip_recovers_the_truth(simulated, tmp_path):
    # the study's own prior, as the simulation drew the truth from it (a log's default is diffuse)
    result = _invoke("calibrate", "scale-bias", "--data", simulated / "data.csv", "--out", tmp_path, "--prior", "settings")
    assert result.exit_code == 0, result.output + result.stderr
    assert "scale_error" in result.output
    estimates = pd.read_csv(tmp_path / "estimates.csv")
    assert list(estimates.columns) == ESTIMATE_COLUMNS and len(estimates) == 300
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert SUMMARY_KEYS <= set(summary)
    assert summary["samples_used"] == 300
    assert np.array(summary["theta_covariance"]).shape == (2, 2)
    assert summary["theta"] == pytest.approx(estimates[["theta1", "theta2"]].iloc[-1].tolist(), rel=1e-15)


def _scale_bias_z(count: int, seed: int, scenario=None):
    """(estimate - truth) / sigma of scale_error and bias, (count, 2), over ``count`` logs drawn from the
    study (its prior, which the calibration takes with --prior settings): the calibrate job's filter."""
    from kalcal.scenarios.scale_bias.calibration import calibrate_scale_bias
    from kalcal.scenarios import build_scenario
    from kalcal.scenarios.scale_bias.theta import scale_bias_from_theta
    from kalcal.scenarios.scale_bias.simulation import sample_scale_bias

    scenario = build_scenario("scale-bias") if scenario is None else scenario
    samples = sample_scale_bias(scenario, np.random.default_rng(seed), count)
    z = np.empty((count, 2))
    for i in range(count):
        result = calibrate_scale_bias(scenario, samples.time, samples.reference[i], samples.sensor[i], prior="settings")
        a, b, cov = result.scale_bias()
        true_a, true_b = scale_bias_from_theta(samples.theta[i, -1])
        z[i] = (a - true_a) / np.sqrt(cov[0, 0]), (b - true_b) / np.sqrt(cov[1, 1])
    return z


def test_the_sigmas_are_right_from_both_sides_over_seeds():
    """scale_error's and bias's z-scores over 150 simulated logs (seed 20240) have a variance within its
    chi-square bounds and a mean within its normal bound (family 0.001): a sigma too large fails as one
    too small does (|est - truth| < 4 sigma passed any sigma too large). Measured over 400: variances
    0.94 and 1.04."""
    from tests._helpers import assert_standard_normal_spread

    z = _scale_bias_z(150, 20240)
    assert_standard_normal_spread(z, what="scale-bias (scale_error, bias)")
    with pytest.raises(AssertionError, match="variance of z"):  # not vacuous: a sigma doubled fails
        assert_standard_normal_spread(z / 2.0, what="sigma doubled")


@pytest.mark.slow
def test_the_sigmas_are_right_from_both_sides_over_many_seeds():
    """As above over 2,000 logs (bounds about +-0.11 on the variance)."""
    from tests._helpers import assert_standard_normal_spread

    assert_standard_normal_spread(_scale_bias_z(2000, 20241), what="scale-bias, 2,000 logs")


def test_parquet_renamed_columns_and_no_time(simulated, tmp_path):
    data = pd.read_csv(simulated / "data.csv")
    csv = _invoke("calibrate", "scale-bias", "--data", simulated / "data.csv", "--out", tmp_path / "csv")
    assert csv.exit_code == 0
    path = tmp_path / "log.parquet"
    data.rename(columns={"reference": "ref_g", "sensor": "dut_g"}).to_parquet(path)
    result = _invoke("calibrate", "scale-bias", "--data", path, "--reference", "ref_g", "--sensor", "dut_g", "--out", tmp_path / "pq")
    assert result.exit_code == 0, result.output + result.stderr
    from_csv = json.loads((tmp_path / "csv" / "summary.json").read_text())
    from_parquet = json.loads((tmp_path / "pq" / "summary.json").read_text())
    assert from_parquet["theta"] == from_csv["theta"] and from_parquet["bias_std"] == from_csv["bias_std"]
    # A two-column log: sample k is put at k / scenario.rate.
    two = tmp_path / "two.csv"
    data[["reference", "sensor"]].to_csv(two, index=False, float_format="%.17g")
    result = _invoke("calibrate", "scale-bias", "--data", two, "--out", tmp_path / "two")
    assert result.exit_code == 0, result.output + result.stderr
    estimates = pd.read_csv(tmp_path / "two" / "estimates.csv")
    np.testing.assert_allclose(estimates["time"], data["time"], rtol=1e-12)
    assert json.loads((tmp_path / "two" / "summary.json").read_text())["theta"] == from_csv["theta"]


def test_settings_reach_the_filter(simulated, tmp_path):
    result = _invoke(
        "calibrate", "scale-bias", "--data", simulated / "data.csv", "--out", tmp_path,
        "--set", "filter.reference_noise_std=0.4", "--set", "scenario.unit=K",
    )
    assert result.exit_code == 0, result.output + result.stderr
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["settings"]["filter"]["reference_noise_std"] == 0.4
    assert summary["units"]["bias"] == "K"
    assert summary["mean_nis"] < 0.5  # the filter now expects twice the noise


@pytest.fixture()
def bad_logs(tmp_path):
    base = pd.DataFrame({"time": [0.1, 0.2, 0.3], "reference": [1.0, 2.0, 3.0], "sensor": [1.1, 2.1, 2.9]})
    logs = {}
    logs["text"] = base.astype(object).copy()
    logs["text"].loc[1, "sensor"] = "oops"
    logs["backwards"] = base.copy()
    logs["backwards"].loc[2, "time"] = 0.15
    paths = {}
    for name, frame in logs.items():
        paths[name] = tmp_path / f"{name}.csv"
        frame.to_csv(paths[name], index=False)
    paths["empty"] = tmp_path / "empty.csv"
    paths["empty"].write_text("time,reference,sensor\n")
    paths["good"] = tmp_path / "good.csv"
    base.to_csv(paths["good"], index=False)
    return paths


def test_bad_inputs_are_one_line_errors(bad_logs, tmp_path):
    out = tmp_path / "out"
    _one_line_error(_invoke("calibrate", "scale-bias", "--out", out), "--data", "required")
    _one_line_error(_invoke("calibrate", "scale-bias", "--data", tmp_path / "nope.csv", "--out", out), "nope.csv", "no such file")
    _one_line_error(_invoke("calibrate", "scale-bias", "--data", bad_logs["text"], "--out", out), "text.csv", "row 2", "'sensor'", "oops")
    _one_line_error(_invoke("calibrate", "scale-bias", "--data", bad_logs["backwards"], "--out", out), "backwards.csv", "row 3", "time")
    _one_line_error(_invoke("calibrate", "scale-bias", "--data", bad_logs["empty"], "--out", out), "empty.csv", "no data rows")
    _one_line_error(
        _invoke("calibrate", "scale-bias", "--data", bad_logs["good"], "--sensor", "dut", "--out", out), "missing column 'dut'"
    )
    _one_line_error(
        _invoke("calibrate", "scale-bias", "--data", bad_logs["good"], "--imu", bad_logs["good"], "--out", out), "--imu/--gps"
    )
    _one_line_error(
        _invoke("calibrate", "scale-bias", "--data", bad_logs["good"], "--set", "truth.scale_error=2", "--out", out),
        "truth.scale_error",
    )
    _one_line_error(_invoke("calibrate", "accel-gps", "--gps", bad_logs["good"], "--out", out), "--imu", "required for accel-gps")
    _one_line_error(_invoke("simulate", "scale-bias", "--set", "scenario.drift=often", "--out", out), "scenario.drift")
    _one_line_error(
        _invoke("verify", "scale-bias", "-n", 200, "--engine", "sampled", "--no-report", "--out", out), "--engine", "scale-bias"
    )


def test_verify_command_writes_summary_and_statistics(tmp_path):
    result = _invoke("verify", "scale-bias", "-n", 1000, "--no-report", "--set", "scenario.duration=5", "--out", tmp_path)
    assert result.exit_code == 0, result.output + result.stderr
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["scenario"] == "scale-bias" and summary["realizations"] == 1000
    assert (tmp_path / "stats.nc").is_file()
