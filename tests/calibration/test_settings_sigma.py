"""The bias sigma that carries the noise settings' uncertainty, and the sigma the diagnostics disown.

The 10x case: the accelerometer noise 10 times the filter's (truth.accel_noise_std = 0.2 against 0.02
m/s^2 per sample) on the default 30 s scenario, calibrated with trapezoid integration, prior "auto" and
first-fix initialization. The conditional sigma's z-scores are far too wide (root mean square 7.02 over
seeds 0-29 here; the issue's 4.83 came from other calibration options); the
sigma over the settings the log cannot reject must bring their spread to at most the chi-square bound of
a unit spread, and on logs whose settings are right agree with the conditional one within the warning's
factor.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import stats

import kalcal
from kalcal.scenarios.accel_gps.log import prepare_accel_gps_log
from kalcal.scenarios.accel_gps.settings_sigma import WARN_FACTOR, error_variance_terms, settings_sigma
from kalcal.scenarios import build_scenario

SCENARIO = build_scenario("accel-gps", None, ["scenario.integration=trapezoid"])


def _log(seed, accel_noise_std, **extra):
    sim = kalcal.simulate("accel-gps", seed=seed, settings={"truth.accel_noise_std": accel_noise_std, **extra})
    imu, gps = sim.logs["imu"], sim.logs["gps"]
    log = prepare_accel_gps_log(SCENARIO, imu.time.values, imu.accel.values, gps.time.values, gps.position.values,
                                gps.velocity.values, init="first-fix", prior="auto")
    return log, float(sim.logs["truth"].bias.values[-1])


def _z_scores(seeds, accel_noise_std):
    conditional, over, ratios = [], [], []
    for seed in seeds:
        log, truth = _log(seed, accel_noise_std)
        calibration = log.calibrate()
        sigma = settings_sigma(log, calibration)
        error = calibration.bias[-1] - truth
        conditional.append(error / sigma.conditional_bias_std)
        over.append(error / sigma.bias_std)
        ratios.append(sigma.ratio)
    return np.array(conditional), np.array(over), np.array(ratios)


def _sd_bound(n, alpha=0.01):
    """The upper bound on the root mean square of n z-scores of unit spread: sqrt(chi2.ppf(1 - alpha, n) / n)."""
    return float(np.sqrt(stats.chi2.ppf(1 - alpha, n) / n))


def test_the_error_variance_at_the_filters_own_settings_is_its_covariance():
    """c_0 + sum theta_s^2 c_s at the filter's settings is P_bb itself: the decomposition is exact."""
    log, _ = _log(0, 0.02)
    for values in ({}, {"filter.accel_noise_std": 0.2, "filter.gps_velocity_std": 0.07}):
        calibration = log.calibrate(values)
        base, coefficients = error_variance_terms(log, calibration, values)
        settings = {key: log.settings_value(key) for key in coefficients} | values
        variance = base + sum(c * settings[key] ** 2 for key, c in coefficients.items())
        assert variance == pytest.approx(calibration.covariance[-1, 2, 2], rel=1e-8)


def test_the_error_variance_of_a_mismatched_filter_matches_simulated_errors():
    """The error variance of the 0.02-filter's estimate under the 0.2-truth, against 200 simulated logs:
    their mean squared error lies within its chi-square(200) bounds at 0.999 of the computed variance."""
    errors, variances = [], []
    for seed in range(200, 400):
        log, truth = _log(seed, 0.2, **{"scenario.duration": 10.0})
        calibration = log.calibrate()
        base, coefficients = error_variance_terms(log, calibration)
        settings = {key: log.settings_value(key) for key in coefficients} | {"filter.accel_noise_std": 0.2}
        variances.append(base + sum(c * settings[key] ** 2 for key, c in coefficients.items()))
        errors.append(calibration.bias[-1] - truth)
    statistic = float(np.sum(np.square(errors) / np.array(variances)))
    low, high = stats.chi2.ppf([0.0005, 0.9995], len(errors))
    assert low <= statistic <= high, (statistic, low, high)


def _report(name, z):
    print(f"{name}: sd of z {np.sqrt(np.mean(z**2)):.3f} over {z.size} logs")


def test_the_settings_sigma_carries_ten_times_the_accelerometer_noise_fast():
    """8 logs of the 10x case: the conditional sigma's z-scores are far too wide (their root mean square
    above the 0.999 chi-square bound of unit spread), the settings sigma's within the 0.99 one."""
    conditional, over, _ = _z_scores(range(8), 0.2)
    _report("conditional", conditional)
    _report("over the settings", over)
    assert np.sqrt(np.mean(conditional**2)) > _sd_bound(8, 0.001)
    assert np.sqrt(np.mean(over**2)) <= _sd_bound(8)


@pytest.mark.slow
def test_the_settings_sigma_carries_ten_times_the_accelerometer_noise_over_30_logs():
    """The issue's case over 30 logs: the settings sigma's z-scores have a root mean square of at most
    sqrt(chi2.ppf(0.99, 30) / 30) = 1.30 (the bound for a unit spread) and the issue's 1.26; the
    conditional one's is far above."""
    conditional, over, _ = _z_scores(range(30), 0.2)
    _report("conditional", conditional)
    _report("over the settings", over)
    sd = float(np.sqrt(np.mean(over**2)))
    assert sd <= min(1.26, _sd_bound(30))
    assert np.sqrt(np.mean(conditional**2)) > _sd_bound(30, 0.001)


#: the settings sigma's cost on logs whose settings are right: its median ratio to the conditional one
#: over seeds 0-29 was 4.68 (4.7 over seeds 100-199); a median of 30 above 6 means the region or its
#: maximum grew (a sigma that is safe by being needlessly large)
MEDIAN_RATIO_LIMIT = 6.0
#: the same over the fast test's 4 logs (seeds 0-3: 4.66), looser for 4 logs: above the single logs'
#: 90% quantile (7.2 over seeds 100-199)
MEDIAN_RATIO_LIMIT_FAST = 8.0


@pytest.mark.slow
def test_with_the_right_settings_the_two_sigmas_agree_within_the_warnings_factor():
    """30 logs whose filter is the truth: the settings sigma exceeds the conditional one by the warning's
    factor on at most 1 of them, its median ratio is at most MEDIAN_RATIO_LIMIT, and its z-scores stay
    within the unit spread's bound.

    At most 1 of 30: WARN_FACTOR (12) lies above the largest ratio measured on right settings (11.0 over
    seeds 100-199: 0 of 100 exceeded it); at a rate of 1% two or more of 30 would exceed it with
    probability 3.6%, and these seeded logs reach at most 9.99."""
    _, over, ratios = _z_scores(range(30), 0.02)
    print(f"ratio: median {np.median(ratios):.3g}, largest {ratios.max():.3g}; factor {WARN_FACTOR:g}; "
          f"z rms over the settings {np.sqrt(np.mean(over**2)):.3f}")
    assert np.count_nonzero(ratios > WARN_FACTOR) <= 1
    assert np.median(ratios) <= MEDIAN_RATIO_LIMIT
    assert np.all(ratios >= 1.0)
    assert np.sqrt(np.mean(over**2)) <= _sd_bound(30)


def test_with_the_right_settings_the_settings_sigma_stays_within_the_factor_fast():
    """4 logs whose filter is the truth: no warning, the settings sigma never below the conditional one,
    and its median ratio at most MEDIAN_RATIO_LIMIT_FAST (its cost bounded from above)."""
    _, _, ratios = _z_scores(range(4), 0.02)
    assert np.all((ratios >= 1.0) & (ratios <= WARN_FACTOR))
    assert np.median(ratios) <= MEDIAN_RATIO_LIMIT_FAST


def test_a_rover_like_log_with_the_default_filter_marks_its_sigma_untrusted_everywhere(tmp_path):
    """examples/rover-like.toml simulated, calibrated with the default filter: the diagnostics say
    inconsistent, so the sigma is marked in summary.json (a sigma-untrusted warning naming `kalcal fit`
    with the same logs and settings), in the result's repr and in the table; the settings sigma is there."""
    from typer.testing import CliRunner

    from kalcal.cli import app

    sim = kalcal.simulate("accel-gps", seed=1, config="examples/rover-like.toml", out=tmp_path / "rover")
    imu, gps = sim.paths["imu"], sim.paths["gps"]
    result = kalcal.calibrate("accel-gps", imu=imu, gps=gps, out=tmp_path / "cal")
    assert not result.sigma_trusted
    assert "NOT trusted" in repr(result)
    summary = json.loads((tmp_path / "cal" / "summary.json").read_text())
    assert summary["sigma_trusted"] is False
    warning = next(w for w in summary["warnings"] if w["code"] == "sigma-untrusted")
    assert f"kalcal fit accel-gps --imu {imu} --gps {gps}" in warning["message"]
    assert summary["settings_sigma"]["bias_std"] >= summary["bias_std"]
    assert result.settings_sigma.bias_std == pytest.approx(summary["settings_sigma"]["bias_std"])
    run = CliRunner().invoke(app, ["calibrate", "accel-gps", "--imu", str(imu), "--gps", str(gps), "--out",
                                   str(tmp_path / "cli"), "--no-settings-sigma", "--set", "filter.gps_position_std=1"])
    assert run.exit_code == 0, run.output
    assert "NOT" in run.stdout and "trusted" in run.stdout, run.stdout
    assert "--set filter.gps_position_std=1" in " ".join(run.output.split())
    assert json.loads((tmp_path / "cli" / "summary.json").read_text())["settings_sigma"] is None


def test_the_figure_title_says_the_sigma_is_not_trusted(tmp_path, monkeypatch):
    """The figure's title carries the note the job gives it."""
    from kalcal.scenarios.accel_gps.calibrate import sigma_note

    note = sigma_note({"sigma_trusted": False, "sigma_untrusted_because": "the diagnostics say inconsistent"})
    assert note.startswith("sigma NOT trusted")
    from kalcal.plots import calibration

    captured = {}

    def save(figure, path):
        captured["title"] = figure.axes[0].get_title()
        return path

    monkeypatch.setattr(calibration, "save", save)
    k = 5
    calibration.plot_calibration(np.arange(k, dtype=float), np.zeros(k), np.ones(k), np.zeros((k, 2)), tmp_path / "c.png", note=note)
    assert "NOT trusted" in captured["title"]


def test_a_consistent_calibration_keeps_its_sigma_trusted():
    """A log whose filter is the truth (seed 0, default scenario): trusted, no sigma-untrusted warning."""
    sim = kalcal.simulate("accel-gps", seed=0)
    result = kalcal.calibrate("accel-gps", imu=sim.logs["imu"], gps=sim.logs["gps"])
    assert result.diagnostics.consistent and result.sigma_trusted
    assert "sigma-untrusted" not in [w.code for w in result.warnings]
