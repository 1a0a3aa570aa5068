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
