"""Velocity-only GPS fixes for accel-gps (``scenario.gps_fixes = "velocity"``): the filter's covariance
pass is the Riccati recursion on H = [0 1 0], verify passes where the model holds, a velocity-only log
calibrates to the bias within its sigma, and what needs a position fix is refused in one line."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from scipy.stats import chi2

from kalcal.models.config import apply_settings
from kalcal.models.settings import SettingError
from kalcal.scenarios.accel_gps.calibration import calibrate_accel_gps, prepare_accel_gps_log
from kalcal.scenarios.accel_gps.problem import accel_gps_problem
from kalcal.scenarios.accel_gps.sampled import sample_accel_gps_logs
from kalcal.scenarios.accel_gps.settings import AccelGpsScenario
from tests._helpers import bonferroni_k

VELOCITY = {"scenario.gps_fixes": "velocity"}


def _scenario(**settings) -> AccelGpsScenario:
    return apply_settings(AccelGpsScenario(), {**VELOCITY, **settings})


def test_the_default_is_position_and_velocity():
    model = AccelGpsScenario().filter_model()
    assert AccelGpsScenario().scenario.gps_fixes == "position+velocity"
    assert np.array_equal(model.h, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def test_the_velocity_only_covariance_pass_is_a_plain_riccati_recursion():
    """The report's per-sample Euler model written out here, propagated sample by sample and updated
    with H = [0 1 0], V = sigma_v^2 at every 40th: the problem's P_k and S_k to rounding."""
    scenario = _scenario()
    problem = accel_gps_problem(scenario)
    t = scenario.truth
    dt, m, n_updates = 1 / 200, 40, 150
    phi = np.array([[1.0, dt, -dt * dt / 2], [0.0, 1.0, -dt], [0.0, 0.0, 1.0]])
    gamma = np.array([[dt * dt / 2], [dt], [0.0]])
    q = t.accel_noise_std**2 * gamma @ gamma.T
    h = np.array([[0.0, 1.0, 0.0]])
    v = np.array([[t.gps_velocity_std**2]])
    assert np.array_equal(problem.filter_model.h, h) and np.allclose(problem.filter_model.v, v, rtol=1e-15)
    cov = np.diag([t.position0_std**2, t.velocity0_std**2, t.bias_std**2])
    posterior, innovation = [], []
    for _ in range(n_updates):
        for _ in range(m):
            cov = phi @ cov @ phi.T + q
        s = h @ cov @ h.T + v
        gain = cov @ h.T / s
        keep = np.eye(3) - gain @ h
        cov = keep @ cov @ keep.T + gain @ v @ gain.T
        posterior.append(cov)
        innovation.append(s)
    np.testing.assert_allclose(problem.schedule.innovation_cov, np.array(innovation), rtol=1e-9)
    scale = np.sqrt(np.einsum("kii->ki", np.array(posterior)))
    np.testing.assert_allclose(problem.schedule.posterior_cov / (scale[:, :, None] * scale[:, None, :]),
                               np.array(posterior) / (scale[:, :, None] * scale[:, None, :]), atol=1e-9)
    # the position is seen only through its prior: its variance never falls below the prior's, while the
    # bias's, seen through dv' = -b, falls far below its prior's
    assert np.all(problem.schedule.posterior_cov[:, 0, 0] >= t.position0_std**2)
    assert problem.schedule.posterior_cov[-1, 2, 2] < 1e-3 * t.bias_std**2


def test_with_the_defaults_position_fixes_add_under_one_percent_to_the_bias_s_sigma():
    """docs/accel-gps.md: the bias sigma after 30 s, velocity-only against position and velocity."""
    both = accel_gps_problem(AccelGpsScenario()).schedule.posterior_cov[-1]
    velocity = accel_gps_problem(_scenario()).schedule.posterior_cov[-1]
    ratio = np.sqrt(velocity[2, 2] / both[2, 2])
    assert 1.0 < ratio < 1.01, ratio
    assert f"{np.sqrt(velocity[2, 2]):.3g}" == "0.000471" and f"{np.sqrt(both[2, 2]):.3g}" == "0.000468"


def test_the_truth_draws_only_the_velocity_fix_noise():
    """One normal fewer per interval than with position fixes, and the exact truth's measurement is 1-d."""
    both, velocity = accel_gps_problem(AccelGpsScenario()), accel_gps_problem(_scenario())
    assert both.sampled_normals - velocity.sampled_normals == 150
    assert velocity.truth.h.shape == (1, 3) and velocity.info.measurement_names == ("velocity",)
    states, z = velocity.sample(np.random.default_rng(1), 5, "sampled")
    assert z.shape == (5, 150, 1)


@pytest.mark.parametrize("engine", ["exact", "sampled"])
def test_verify_with_velocity_only_fixes_passes_with_the_trapezoid_rule(tmp_path, engine):
    """Every check, both engines, at a modest N (the default N's run is in docs/accel-gps.md)."""
    ran = subprocess.run(
        [sys.executable, "-m", "kalcal", "verify", "accel-gps", "-n", "4096", "--seed", "3", "--engine", engine,
         "--set", "scenario.gps_fixes=velocity", "--set", "scenario.integration=trapezoid", "--out", str(tmp_path),
         "--no-report", "--long-run", "0", "--threads", "1", "--strict"],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert ran.returncode == 0, ran.stdout[-3000:] + ran.stderr[-3000:]
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["settings"]["scenario"]["gps_fixes"] == "velocity"
    assert summary["verdict"] == "pass"


def test_a_velocity_only_log_calibrates_to_the_bias_within_its_sigma():
    """100 simulated velocity-only logs (discrete truth: the filter's model holds): z = (b_hat - b) / sigma
    is N(0, 1), so sum z^2 lies within chi2(100)'s two-sided 0.999 interval and every |z| within the
    Bonferroni bound of 100 normals at family-wise 1e-3; no position is given to the calibration."""
    scenario = _scenario(**{"scenario.truth": "discrete"})
    z = []
    for seed in range(100):
        logs = sample_accel_gps_logs(scenario, np.random.default_rng(1000 + seed))
        assert np.all(np.isnan(logs.gps_position))
        result = calibrate_accel_gps(scenario, logs.sample_time, logs.accel[0], logs.fix_time, None, logs.gps_velocity[0],
                                     init="first-fix", prior="diffuse")
        assert result.residual.shape == (149, 1)
        assert [w.code for w in result.warnings] == ["velocity-only-fixes"]
        z.append((result.bias[-1] - logs.bias[0, -1]) / result.std[-1, 2])
    z = np.array(z)
    low, high = chi2.ppf([0.0005, 0.9995], z.size)
    assert low <= np.sum(z**2) <= high, np.sum(z**2)
    assert np.max(np.abs(z)) <= bonferroni_k(z.size, 1e-3)


def test_a_velocity_only_log_skips_the_position_checks():
    """Positions that would be refused (beyond any physical limit) are not read at all."""
    scenario = _scenario()
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(5))
    nonsense = np.full(logs.fix_time.size, 1e30)
    log = prepare_accel_gps_log(scenario, logs.sample_time, logs.accel[0], logs.fix_time, nonsense, logs.gps_velocity[0])
    assert log.warnings[0].code == "velocity-only-fixes" and "filter.gps_position_std" not in log.available_keys()
    with pytest.raises(Exception, match="implausible|limit|1e\\+30"):
        prepare_accel_gps_log(AccelGpsScenario(), logs.sample_time, logs.accel[0], logs.fix_time, nonsense, logs.gps_velocity[0])


def test_the_position_fix_s_settings_are_refused_on_a_velocity_only_log_in_one_line():
    scenario = _scenario()
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(5))
    log = prepare_accel_gps_log(scenario, logs.sample_time, logs.accel[0], logs.fix_time, None, logs.gps_velocity[0])
    for key in ("filter.gps_position_std", "log.position_std_multiplier"):
        with pytest.raises(SettingError, match="velocity-only") as raised:
            log.loglik({key: 2.0})
        assert "\n" not in str(raised.value) and key in str(raised.value)


def test_an_unknown_kind_of_fix_is_refused_in_one_line_with_status_2():
    ran = subprocess.run([sys.executable, "-m", "kalcal", "analyze", "accel-gps", "--set", "scenario.gps_fixes=position"],
                         capture_output=True, text=True, timeout=300)
    assert ran.returncode == 2
    lines = ran.stderr.strip().splitlines()
    assert len(lines) == 1 and "scenario.gps_fixes" in lines[0] and "velocity" in lines[0], ran.stderr


# --- kalcal calibrate and kalcal fit on a velocity-only log -------------------------------------------------


def _kalcal(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "kalcal", *map(str, args)], capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def velocity_logs(tmp_path_factory):
    """A simulated velocity-only log (its position column empty) and the same log with no position column,
    with the truth's bias at the last fix."""
    import pandas as pd

    root = tmp_path_factory.mktemp("velocity")
    ran = _kalcal("simulate", "accel-gps", "--set", "scenario.gps_fixes=velocity", "--seed", "1", "--out", root / "sim")
    assert ran.returncode == 0, ran.stderr
    gps = pd.read_csv(root / "sim" / "gps.csv")
    assert list(gps.columns) == ["time", "position", "velocity"] and gps["position"].isna().all()
    gps.drop(columns="position").to_csv(root / "no_position.csv", index=False)
    truth = pd.read_csv(root / "sim" / "truth.csv")
    bias = float(np.interp(gps["time"].iloc[-1], truth["time"], truth["bias"]))
    return {"imu": root / "sim" / "imu.csv", "nan": root / "sim" / "gps.csv", "none": root / "no_position.csv",
            "bias": bias, "root": root}


def _bias_and_diagnostics_hold(summary: dict, bias: float) -> None:
    """The bias within 3.29 of its sigma (two-sided 1e-3 for z = (b_hat - b) / sigma ~ N(0, 1)); the
    diagnostics consistent, their mean NIS within chi2(K)'s two-sided bounds at the NIS test's share
    (1 - 0.99) / 2 of one component (with two, the bounds would be chi2(2K)'s, about 2)."""
    from scipy.stats import norm

    z = (summary["bias"] - bias) / summary["bias_std"]
    assert abs(z) <= norm.isf(1e-3 / 2), z
    d = summary["diagnostics"]
    share = (1 - d["confidence"]) / 2
    fixes = d["fixes"]
    low, high = chi2.ppf([share / 2, 1 - share / 2], fixes) / fixes
    assert d["nis_lower"] == pytest.approx(low, rel=1e-9) and d["nis_upper"] == pytest.approx(high, rel=1e-9)
    assert low <= d["mean_nis"] <= high and d["consistent"], d["verdict"]
    assert len(d["ljung_box_statistic"]) == 1  # the velocity's series alone
    # nothing measures the position: its sigma never falls below its prior's (the filter's, unset: the truth's)
    settings = summary["settings"]
    assert summary["position_std"] >= (settings["filter"]["position0_std"] or settings["truth"]["position0_std"])


@pytest.mark.parametrize("log", ["nan", "none"])
def test_calibrate_takes_a_velocity_only_log_with_or_without_a_position_column(velocity_logs, tmp_path, log):
    import pandas as pd

    ran = _kalcal("calibrate", "accel-gps", "--imu", velocity_logs["imu"], "--gps", velocity_logs[log],
                  "--set", "scenario.gps_fixes=velocity", "--out", tmp_path)
    assert ran.returncode == 0, ran.stderr[-3000:]
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["settings"]["scenario"]["gps_fixes"] == "velocity"
    assert [w["code"] for w in summary["warnings"]] == ["velocity-only-fixes"]
    _bias_and_diagnostics_hold(summary, velocity_logs["bias"])
    # estimates.csv keeps its columns: the position innovation, which a velocity fix has not, is NaN
    estimates = pd.read_csv(tmp_path / "estimates.csv")
    assert list(estimates.columns) == ["time", "position", "velocity", "bias", "position_std", "velocity_std", "bias_std",
                                       "nis", "innovation_position", "innovation_velocity"]
    assert estimates["innovation_position"].isna().all() and estimates["innovation_velocity"].notna().all()
    # one component: each fix's NIS is its velocity innovation squared
    np.testing.assert_allclose(estimates["nis"], estimates["innovation_velocity"] ** 2, rtol=1e-12)
    assert (tmp_path / "calibration.png").stat().st_size > 0


def test_both_velocity_only_logs_calibrate_alike(velocity_logs, tmp_path):
    """The position column is not read: with it empty or absent, the same numbers."""
    sums = []
    for log in ("nan", "none"):
        ran = _kalcal("calibrate", "accel-gps", "--imu", velocity_logs["imu"], "--gps", velocity_logs[log], "--set",
                      "scenario.gps_fixes=velocity", "--out", tmp_path / log, "--no-settings-sigma")
        assert ran.returncode == 0, ran.stderr[-3000:]
        sums.append(json.loads((tmp_path / log / "summary.json").read_text()))
    for key in ("bias", "bias_std", "velocity", "fixes_used"):
        assert sums[0][key] == sums[1][key], key
    assert sums[0]["diagnostics"]["mean_nis"] == sums[1]["diagnostics"]["mean_nis"]


@pytest.mark.parametrize("command", ["calibrate", "fit"])
@pytest.mark.parametrize("log", ["nan", "none"])
def test_a_velocity_only_log_under_the_default_fixes_is_refused_naming_the_position_column(velocity_logs, tmp_path, command, log):
    ran = _kalcal(command, "accel-gps", "--imu", velocity_logs["imu"], "--gps", velocity_logs[log], "--out", tmp_path)
    assert ran.returncode == 2
    lines = ran.stderr.strip().splitlines()
    assert len(lines) == 1 and "'position'" in lines[0] and "scenario.gps_fixes=velocity" in lines[0], ran.stderr
    assert str(velocity_logs[log].name) in lines[0]


def test_fit_on_a_velocity_only_log_goes_back_into_calibrate(velocity_logs, tmp_path):
    """The fit leaves the position fix's std out of its defaults, writes the kind of fix in filter.toml's
    [scenario], and calibrate --config takes the file as it is (no --set), to the bias within its sigma."""
    import tomllib

    ran = _kalcal("fit", "accel-gps", "--imu", velocity_logs["imu"], "--gps", velocity_logs["none"],
                  "--set", "scenario.gps_fixes=velocity", "--out", tmp_path / "fit")
    assert ran.returncode == 0, ran.stderr[-3000:]
    document = json.loads((tmp_path / "fit" / "fit.json").read_text())
    assert document["free"] == ["filter.accel_noise_density", "filter.bias_walk_density", "filter.gps_velocity_std"]
    assert document["adequate"], document["adequacy"]
    config = tomllib.loads((tmp_path / "fit" / "filter.toml").read_text())
    assert config["scenario"]["gps_fixes"] == "velocity"
    # the fitted velocity noise within its interval of the simulation's 0.04 m/s
    interval = document["parameters"]["filter.gps_velocity_std"]
    assert interval["ci_low"] <= AccelGpsScenario().truth.gps_velocity_std <= interval["ci_high"], interval
    ran = _kalcal("calibrate", "accel-gps", "--imu", velocity_logs["imu"], "--gps", velocity_logs["none"],
                  "--config", tmp_path / "fit" / "filter.toml", "--out", tmp_path / "cal")
    assert ran.returncode == 0, ran.stderr[-3000:]
    summary = json.loads((tmp_path / "cal" / "summary.json").read_text())
    assert summary["settings"]["scenario"]["gps_fixes"] == "velocity"
    assert summary["settings"]["filter"]["gps_velocity_std"] == config["filter"]["gps_velocity_std"]
    _bias_and_diagnostics_hold(summary, velocity_logs["bias"])


def test_the_api_fit_s_settings_go_back_into_calibrate(velocity_logs, tmp_path, monkeypatch):
    """... and calibration.png draws the velocity's innovations alone."""
    import kalcal
    import kalcal.plots.calibration as plots

    fit = kalcal.fit("accel-gps", imu=velocity_logs["imu"], gps=velocity_logs["none"], settings=VELOCITY)
    assert fit.settings["scenario"]["gps_fixes"] == "velocity"
    result = kalcal.calibrate("accel-gps", imu=velocity_logs["imu"], gps=velocity_logs["none"], settings=fit.settings,
                              settings_sigma=False)
    _bias_and_diagnostics_hold(result.summary, velocity_logs["bias"])
    drawn = {}
    plot = plots.plot_calibration
    monkeypatch.setattr(plots, "plot_calibration", lambda *a, **k: drawn.update(normalized=a[3], names=k["names"]) or plot(*a, **k))
    result.save(tmp_path / "cal")
    assert drawn["names"] == ("velocity",) and drawn["normalized"].shape == (result.summary["fixes_used"], 1)
    assert np.all(np.isfinite(drawn["normalized"]))


@pytest.mark.parametrize("key", ["filter.gps_position_std", "log.position_std_multiplier"])
def test_fit_refuses_the_position_fix_s_settings_on_a_velocity_only_log(velocity_logs, tmp_path, key):
    ran = _kalcal("fit", "accel-gps", "--imu", velocity_logs["imu"], "--gps", velocity_logs["none"],
                  "--set", "scenario.gps_fixes=velocity", "--free", key, "--out", tmp_path)
    assert ran.returncode == 2
    lines = ran.stderr.strip().splitlines()
    assert len(lines) == 1 and key in lines[0] and "velocity-only" in lines[0], ran.stderr


def test_a_topic_without_the_velocity_field_is_refused_in_one_line_under_velocity_only_fixes():
    """A GPS topic read from a bag or ULog (a frame naming its source) with no velocity field: its name,
    the field asked for and how to name one; its position field is not asked for."""
    import pandas as pd

    from kalcal.errors import DataError
    from kalcal.scenarios.accel_gps.calibrate import GPS_ROLES, read_gps_log

    frame = pd.DataFrame({"time": [0.0, 0.2], "/odom.pose.pose.position.x": [0.0, 1.0]})
    frame.attrs["source"] = "run.bag topic /odom"
    columns = {**{role: role for role in GPS_ROLES}, "velocity": "/odom.twist.twist.linear.x"}
    with pytest.raises(DataError, match=r"run\.bag topic /odom: has no velocity '/odom\.twist\.twist\.linear\.x'.*TOPIC\.FIELD") as raised:
        read_gps_log(_scenario(), frame, columns)
    assert "\n" not in str(raised.value) and "position" not in str(raised.value)
    frame["/odom.twist.twist.linear.x"] = [1.0, 1.0]
    name, gps = read_gps_log(_scenario(), frame, columns)
    assert name == "run.bag topic /odom" and gps["position"] is None and list(gps["velocity"]) == [1.0, 1.0]


@pytest.mark.parametrize("fixes", ["velocity", "position+velocity"])
def test_verify_with_the_euler_scheme_against_the_analytic_truth_fails_through_the_model_error(fixes):
    """docs/accel-gps.md: with the report's Euler scheme against the analytic truth the model error fails
    the checks with velocity-only fixes as it does with position fixes: mean_error fails, explained by the
    model error the summary names (the Euler scheme's), and every other failure by the mean error."""
    import kalcal

    result = kalcal.verify("accel-gps", n=4096, seed=0, long_run=0, settings={"scenario.gps_fixes": fixes})
    summary = result.to_dict()
    assert summary["settings"]["scenario"]["gps_fixes"] == fixes
    assert summary["settings"]["scenario"]["integration"] == "euler" and summary["settings"]["scenario"]["truth"] == "analytic"
    assert summary["verdict"] == "fail"
    assert "euler integration" in summary["model_error"]["cause"]
    tests = {t["name"]: t for t in summary["tests"]}
    assert not tests["mean_error"]["passed"] and tests["mean_error"]["cause"]["explained_by"] == "model_error"
    for name, test in tests.items():
        if not test["passed"]:
            assert test["cause"]["explained_by"] in ("model_error", "mean_error"), (name, test["cause"])
