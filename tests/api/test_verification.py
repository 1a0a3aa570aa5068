"""``kalcal verify`` end to end: outputs, exit codes, and the report's headline numbers."""

import json
import re

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from kalcal.cli import app
from kalcal.api.verification import verify
from kalcal.scenarios import build_scenario
from kalcal.stats.bounds import normal_bound

runner = CliRunner()
SHORT = ["--set", "scenario.duration=4", "--no-report", "--long-run", "0"]


def _run(tmp_path, *args):
    return runner.invoke(app, ["verify", "-n", "3000", "--out", str(tmp_path), *SHORT, *args])


def test_verify_writes_summary_and_statistics(tmp_path):
    result = _run(tmp_path, "--seed", "4")
    assert result.exit_code == 0, result.output
    summary = json.loads((tmp_path / "summary.json").read_text())
    for key in ("scenario", "realizations", "seed", "engine", "verdict", "tests", "final", "timing"):
        assert key in summary
    assert summary["realizations"] == 3000 and summary["seed"] == 4 and summary["engine"] == "exact"
    assert [t["name"] for t in summary["tests"]] == ["mean_error", "covariance", "orthogonality", "residual_whiteness", "nis", "shape"]
    for test in summary["tests"]:
        assert set(test) >= {"name", "passed", "statistic", "lower", "upper", "detail", "confidence", "comparisons"}
        # p-values and causes as data, not only in the detail
        assert test["passed"] == (test["pvalue"] >= 1 - test["confidence"])
        assert set(test["cause"]) == {"explained_by", "direction", "reason"}
        assert test["cause"]["reason"] is None or test["detail"].endswith(test["cause"]["reason"])
    covariance = summary["tests"][1]
    assert [part["name"] for part in covariance["parts"]] == ["elements", "centered_nees"]
    assert all(part["alpha"] == pytest.approx(0.005) for part in covariance["parts"])
    assert all(test["parts"] == [] for test in summary["tests"] if test["name"] not in ("covariance", "residual_whiteness", "shape"))
    shape = summary["tests"][5]
    assert [part["name"] for part in shape["parts"]] == ["nees", "nis"]
    assert all(part["alpha"] == pytest.approx(0.005) for part in shape["parts"])
    assert shape["pvalue"] == pytest.approx(min(1.0, 2 * min(part["pvalue"] for part in shape["parts"])))
    whiteness = summary["tests"][3]
    assert [part["name"] for part in whiteness["parts"]] == ["pairs", "portmanteau"]
    assert all(part["alpha"] == pytest.approx(0.005) for part in whiteness["parts"])
    assert whiteness["pvalue"] == pytest.approx(min(1.0, 2 * min(part["pvalue"] for part in whiteness["parts"])))
    assert whiteness["passed"] == all(part["passed"] for part in whiteness["parts"])
    assert (whiteness["statistic"], whiteness["upper"]) == (whiteness["parts"][0]["statistic"], whiteness["parts"][0]["upper"])
    assert whiteness["comparisons"] == sum(part["comparisons"] for part in whiteness["parts"])
    mean_error = summary["tests"][0]
    assert not mean_error["passed"] and mean_error["cause"]["explained_by"] == "model_error"
    assert np.array(summary["final"]["filter_covariance"]).shape == (3, 3)
    assert summary["timing"]["monte_carlo_s"] > 0
    with xr.open_dataset(tmp_path / "stats.nc") as stats:
        assert stats.sizes["time"] == 20 and stats.sizes["state"] == 3
        assert stats["residual_second_moment"].dims == ("time", "measurement", "time2", "measurement2")
        np.testing.assert_allclose(stats["filter_cov"].values[-1], summary["final"]["filter_covariance"])
    assert "mean_error" in result.output and "FAIL" in result.output


ZERO_SPREAD_MODEL = """
steps_per_update = 10
updates = 10
sample_period = 0.1
phi   = [[1.0, 0.1, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
gamma = [[0.005], [0.1], [0.0]]
h     = [[1.0, 0.0, 0.0]]
w     = [[0.04]]
v     = [[4.0]]
x0    = [0.0, 10.0, 0.0]
m0    = [[25.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]

[truth]
x0 = [0.0, 10.0, 0.5]
m0 = [[25.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]]
"""


def test_a_state_without_spread_and_with_a_mean_error_fails_mean_error(tmp_path):
    """x3 is 0.5 in every realization of the truth and never observed: e_3 = 0.5 with zero variance.

    Zero standard error used to count as a pass; a nonzero mean with no spread is a failure.
    """
    model = tmp_path / "zero_spread.toml"
    model.write_text(ZERO_SPREAD_MODEL)
    result = runner.invoke(app, ["verify", str(model), "-n", "2000", "--out", str(tmp_path / "out"), "--no-report"])
    assert result.exit_code == 0, result.output
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    mean_error = summary["tests"][0]
    assert not mean_error["passed"] and mean_error["pvalue"] == 0.0
    assert mean_error["statistic"] is None  # infinite: JSON has no inf
    assert "x3 at t = 1 s: mean error 0.5 with zero standard error" in mean_error["detail"]
    assert "10 comparison(s) with zero standard error and a nonzero mean error, counted as failed" in mean_error["detail"]
    # the filter run on the truth's mean predicts exactly this offset
    assert mean_error["cause"]["explained_by"] == "model_error"
    # x3's ensemble variance is 0 against P = 1: underconfident (a variance ratio of 0 used to be passed over)
    assert summary["tests"][1]["cause"]["direction"] == "underconfident"
    assert re.search(r"mean_error\s*│\s*inf\s*│\s*≤ [0-9.]+\s*│\s*0\s*│\s*FAIL", result.output), result.output


def test_strict_exit_status_follows_the_verdict(tmp_path):
    assert _run(tmp_path / "a", "--strict").exit_code == 1  # the report's Euler mean error
    assert _run(tmp_path / "b", "--strict", "--set", "scenario.truth=discrete", "--seed", "1").exit_code == 0


@pytest.mark.parametrize(
    "args, message",
    [
        (["--set", "truth.bias_sd=1"], "truth.bias_sd"),
        (["--set", "filter.accel_noise_std=-1"], "filter.accel_noise_std"),
        (["--engine", "fast"], "--engine"),
        (["-n", "1"], "-n"),
        (["--confidence", "1.5"], "--confidence"),
        (["--set", "scenario.gps_rate=3"], "scenario.gps_rate"),
    ],
)
def test_bad_input_is_one_line_and_status_2(tmp_path, args, message):
    result = _run(tmp_path, *args)
    assert result.exit_code == 2
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and message in lines[0], result.output


def test_same_seed_same_summary(tmp_path):
    scenario = build_scenario("accel-gps", None, ["scenario.duration=4"])
    one = verify(scenario, 5000, 9, tmp_path / "one", workers=1, long_run=0)
    two = verify(scenario, 5000, 9, tmp_path / "two", workers=2, long_run=0)
    assert json.dumps(one.summary["tests"]) == json.dumps(two.summary["tests"])
    np.testing.assert_array_equal(one.statistics.residual_second_moment, two.statistics.residual_second_moment)


def test_long_run_is_written_without_residual_pairs(tmp_path):
    scenario = build_scenario("accel-gps", None, ["scenario.duration=2"])
    outcome = verify(scenario, 3000, 1, tmp_path, long_run=6.0)
    with xr.open_dataset(tmp_path / "stats_long.nc") as long:
        assert long.sizes["time"] == 30 and "residual_second_moment" not in long
    assert outcome.summary["long_run"]["duration"] == 6.0


@pytest.mark.slow
def test_report_defaults_at_full_size(tmp_path):
    """3 x 10^5 realizations: the Euler mean error (2.0 sigma in velocity at 30 s, 1.6 sigma in bias at 18 s)."""
    outcome = verify(build_scenario("accel-gps"), 300_000, 0, tmp_path, long_run=0)
    checks = {c.name: c for c in outcome.checks}
    assert not checks["mean_error"].passed and "Explained by the predicted systematic error" in checks["mean_error"].detail
    s = outcome.statistics
    sigma = np.sqrt(np.diagonal(s.filter_cov, axis1=1, axis2=2))
    in_sigma = s.mean_error / sigma
    se = np.sqrt(np.diagonal(s.error_cov, axis1=1, axis2=2) / s.count) / sigma
    assert abs(abs(in_sigma[-1, 1]) - 2.0) < 0.05 + 5 * se[-1, 1]
    k18 = int(np.argmin(np.abs(outcome.dataset["time"].values - 18.0)))
    assert abs(abs(in_sigma[k18, 2]) - 1.6) < 0.05 + 5 * se[k18, 2]


@pytest.mark.slow
def test_trapezoid_sampled_engine_at_1e5(tmp_path):
    """The issue's measurement: 200 Hz simulation, N = 10^5: mean error in bounds, variances within 1% of P."""
    scenario = build_scenario("accel-gps", None, ["scenario.integration=trapezoid"])
    outcome = verify(scenario, 100_000, 2, tmp_path, engine="sampled", long_run=0)
    checks = {c.name: c for c in outcome.checks}
    assert checks["mean_error"].passed and checks["covariance"].passed
    s = outcome.statistics
    ratio = np.diagonal(s.error_cov, axis1=1, axis2=2) / np.diagonal(s.filter_cov, axis1=1, axis2=2)
    # a sample variance has relative sd sqrt(2 / (N - 1)); Bonferroni over every state and update
    bound = normal_bound(0.999, ratio.size) * np.sqrt(2 / (s.count - 1))
    assert np.all(np.abs(ratio - 1) < bound)
