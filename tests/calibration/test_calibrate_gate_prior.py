"""``kalcal calibrate accel-gps`` on a log: the gate's rejections in the outputs, the bias's prior and its conflicts."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from kalcal.scenarios.accel_gps.calibration import calibrate_accel_gps, prior_conflict
from kalcal.cli import app
from kalcal.scenarios.accel_gps.calibrate import compute_accel_gps_calibration
from kalcal.scenarios import build_scenario
from kalcal.scenarios.accel_gps.sampled import sample_accel_gps_logs

BAD = np.array([30, 75, 120])  # 0-based fixes given gross position errors


@pytest.fixture(scope="module")
def logs():
    scenario = build_scenario("accel-gps")
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(7), 1)
    imu = pd.DataFrame({"time": logs.sample_time, "accel": logs.accel[0]})
    position = logs.gps_position[0].copy()
    position[BAD] += np.array([50.0, -60.0, 70.0])
    gps = pd.DataFrame({"time": logs.fix_time, "position": position, "velocity": logs.gps_velocity[0]})
    return imu, gps, logs


def _scenario(*extra):
    return build_scenario("accel-gps", assignments=["scenario.integration=trapezoid", *extra])


def test_the_summary_counts_and_lists_the_rejected_fixes(logs):
    imu, gps, _ = logs
    summary = compute_accel_gps_calibration(_scenario(), imu, gps, gate=0.999).summary
    assert summary["gate"] == 0.999
    assert summary["fixes_rejected"] == 3 and summary["rejected_rows"] == list(BAD + 1)
    ungated = compute_accel_gps_calibration(_scenario(), imu, gps).summary
    assert ungated["gate"] is None and ungated["fixes_rejected"] == 0 and ungated["rejected_rows"] == []
    # the diagnostics leave the rejected fixes out: the outliers fail them ungated, not gated
    assert not ungated["diagnostics"]["consistent"] and summary["diagnostics"]["consistent"]


def test_the_terminal_names_the_rejected_fixes(logs, tmp_path):
    imu, gps, _ = logs
    imu.to_csv(tmp_path / "imu.csv", index=False)
    gps.to_csv(tmp_path / "gps.csv", index=False)
    args = ["calibrate", "accel-gps", "--imu", str(tmp_path / "imu.csv"), "--gps", str(tmp_path / "gps.csv")]
    result = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "cal"), "--gate", "0.999"], catch_exceptions=False)
    assert result.exit_code == 0, result.stderr
    assert f"3 fix(es) rejected (GPS rows {', '.join(map(str, BAD + 1))})" in result.stdout
    assert json.loads((tmp_path / "cal" / "summary.json").read_text())["rejected_rows"] == list(BAD + 1)
    bad = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "bad"), "--gate", "1.5"], catch_exceptions=False)
    assert bad.exit_code == 2 and "--gate" in bad.stderr and len(bad.stderr.strip().splitlines()) == 1


def test_a_log_gets_a_diffuse_bias_prior_unless_bias_std_is_given(logs):
    imu, gps, raw = logs
    diffuse = compute_accel_gps_calibration(_scenario(), imu, gps).summary
    assert diffuse["prior"] == {"bias": "diffuse", "bias_std": 1000.0, "likelihood_skip": 1}
    given = compute_accel_gps_calibration(_scenario("filter.bias_std=0.1"), imu, gps).summary
    assert given["prior"] == {"bias": "filter.bias_std", "bias_std": 0.1, "likelihood_skip": 0}
    markov = compute_accel_gps_calibration(_scenario("filter.bias_correlation_time=60"), imu, gps).summary
    assert markov["prior"]["bias"] == "stationary" and markov["prior"]["bias_std"] == 0.1
    # the given prior is the library's default (the old calibration, number for number)
    direct = calibrate_accel_gps(
        _scenario(), imu["time"].to_numpy(), imu["accel"].to_numpy(), *(gps[c].to_numpy() for c in ("time", "position", "velocity")),
        init="first-fix",
    )
    assert given["bias"] == direct.bias[-1]


def test_a_prior_the_data_contradict_is_reported():
    """A true bias of 0.3 m/s^2 against a given prior of 0.01 m/s^2: z = b_hat / sqrt(sigma_0^2 - P_bb)
    is far beyond the 0.999 quantile, so the warning is raised; with the true spread it is not."""
    truth = build_scenario("accel-gps", assignments=["truth.bias_std=0.3"])
    logs = sample_accel_gps_logs(truth, np.random.default_rng(11), 1)
    args = (logs.sample_time, logs.accel[0], logs.fix_time, logs.gps_position[0], logs.gps_velocity[0])
    assert abs(logs.bias[0, -1]) > 0.1  # the draw is a large bias
    tight = calibrate_accel_gps(build_scenario("accel-gps", assignments=["filter.bias_std=0.01"]), *args)
    warning = prior_conflict(tight)
    assert warning is not None and warning.code == "prior-conflict"
    assert prior_conflict(calibrate_accel_gps(truth, *args)) is None
    assert prior_conflict(calibrate_accel_gps(truth, *args, prior="diffuse")) is None


def test_a_walking_bias_that_follows_its_prior_rarely_raises_a_conflict():
    """Truth = filter with a random-walk bias: z = b_hat / sqrt(sigma_0^2 + walk variance - P_bb) is N(0, 1),
    so at 0.999 the warning fires at rate 0.001 (without the walk's variance it fired at about 5%)."""
    from scipy import stats

    from kalcal.scenarios.accel_gps.calibration import bias_walk_variance

    settings = ["truth.bias_walk_std=2e-3", "filter.bias_walk_std=2e-3", "filter.bias_std=0.1"]
    scenario = build_scenario("accel-gps", assignments=settings)
    count = 120
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(2024), count)
    raised = 0
    for i in range(count):
        args = (logs.sample_time, logs.accel[i], logs.fix_time, logs.gps_position[i], logs.gps_velocity[i])
        result = calibrate_accel_gps(scenario, *args)
        walk = bias_walk_variance(scenario, result, logs.sample_time)
        assert walk == pytest.approx(2e-3**2 * (result.time[-1] - result.start_time) * 200.0, rel=1e-9)
        raised += prior_conflict(result, walk_variance=walk) is not None
    assert raised <= stats.binom.ppf(0.999, count, 0.001)
