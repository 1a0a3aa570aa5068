"""The accel-gps bootstrap's logs (kalcal.scenarios.accel_gps.resample): fixes drawn from the fitted filter over
a given log, and ``kalcal fit accel-gps --bootstrap``.

The drawn fixes must follow the filter's own model at the settings they were drawn from: then the filter at
those settings has innovations whose NIS sums, over M drawn logs of K' scored fixes with p components each,
to a chi-square with M K' p degrees of freedom (exactly, up to the diffuse bias's finite 1-sigma, an
effect of order 1e-6). At other settings the sum leaves its bounds: the test can fail.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import kalcal
from kalcal.scenarios import build_scenario
from kalcal.scenarios.accel_gps.log import prepare_accel_gps_log
from kalcal.scenarios.accel_gps.resample import simulate_fixes
from kalcal.stats.distributions import chi2_ppf

AT = {"filter.accel_noise_std": 0.02, "filter.bias_walk_std": 2e-5, "filter.gps_position_std": 1.5,
      "filter.gps_velocity_std": 0.08}


def _log(seed: int, duration: float, *settings: str, init: str = "first-fix", prior: str = "auto"):
    scenario = build_scenario("accel-gps", None, [*settings])
    sim = kalcal.simulate("accel-gps", seed=seed, settings={"scenario.duration": duration})
    imu, gps = sim.logs["imu"], sim.logs["gps"]
    gps = gps.assign(position=gps.position.where(np.arange(len(gps)) % 7 != 3))  # a missing field every 7th fix
    return prepare_accel_gps_log(scenario, imu.time.values, imu.accel.values, gps.time.values, gps.position.values,
                                 gps.velocity.values, init=init, prior=prior)


def _nis_sum(log, draw_at, run_at, logs=40, seed=0):
    """(sum of the scored fixes' NIS over ``logs`` logs drawn at ``draw_at`` and filtered at ``run_at``, its dof)."""
    total, dof = 0.0, 0
    for m in range(logs):
        drawn = simulate_fixes(log, draw_at, np.random.default_rng([seed, m]))
        run = drawn.calibrate(run_at)
        for k in range(drawn.skip, drawn.fixes):
            r, s = run.residual[k], run.innovation_cov[k]
            total += float(r @ np.linalg.solve(s, r))
            dof += r.size
    return total, dof


def _inside(total, dof):
    # two-sided 0.001 bounds of chi-square(dof), from theory
    return chi2_ppf(0.0005, dof) <= total <= chi2_ppf(0.9995, dof)


@pytest.mark.parametrize(
    "settings,init,values",
    [
        ((), "first-fix", AT),  # the fit's default: first fix anchors, diffuse bias skipped
        # the process noise dominates the velocity fixes' innovations: a wrong Q_k draw shows here
        ((), "first-fix", {**AT, "filter.accel_noise_std": 0.5, "filter.bias_walk_std": 2e-3, "filter.gps_velocity_std": 0.005}),
        (("filter.gps_latency=0.12", "filter.scale_std=0.01"), "first-fix", AT),  # latency's H_L and a scale state
        (("filter.bias_std=0.05", "filter.bias_correlation_time=40"), "prior", {**AT, "filter.bias_std": 0.05}),
    ],
    ids=["first-fix-diffuse", "process-dominated", "latency-scale", "prior-gauss-markov"],
)
def test_drawn_fixes_have_chi_square_nis_at_the_settings_they_were_drawn_from(settings, init, values):
    log = _log(1, 60, *settings, init=init)
    total, dof = _nis_sum(log, values, values)
    assert _inside(total, dof), (total, dof, chi2_ppf(0.0005, dof), chi2_ppf(0.9995, dof))


def test_drawn_fixes_leave_the_bounds_at_other_settings_and_hold_the_log():
    log = _log(1, 60)
    wrong = {**AT, "filter.gps_position_std": 1.5 * 1.3}  # the filter believes 30% more position noise
    total, dof = _nis_sum(log, AT, wrong)
    assert total < chi2_ppf(0.0005, dof), (total, dof)
    drawn = simulate_fixes(log, AT, np.random.default_rng(3))
    # only the fixes' values are drawn: times, accelerometer, anchor and the fixes left out are the log's
    assert np.array_equal(drawn.fix_times, log.fix_times) and drawn.accel is log.accel and drawn.first == log.first
    assert drawn.fixes == log.fixes < 300  # the fixes with a NaN field stay out
    assert not np.array_equal(drawn.z_position, log.z_position)
    again = simulate_fixes(log, AT, np.random.default_rng(3))
    assert np.array_equal(again.z_position, drawn.z_position) and np.array_equal(again.z_velocity, drawn.z_velocity)


def test_velocity_only_fixes_are_drawn_without_positions():
    log = _log(2, 60, "scenario.gps_fixes=velocity")
    values = {key: v for key, v in AT.items() if key != "filter.gps_position_std"}
    total, dof = _nis_sum(log, values, values, logs=20)
    assert _inside(total, dof) and dof == 20 * (log.fixes - log.skip)
    assert np.all(np.isnan(simulate_fixes(log, values, np.random.default_rng(0)).z_position))


# kalcal fit accel-gps --bootstrap: the refits are of the same fixes; identical on 1 and 2 threads (B = 6 at 70%,
# the fewest that level allows: 2/(1 - 0.7) - 1 = 5.7).
def test_fit_accel_gps_bootstrap_one_and_two_threads_identical():
    sim = kalcal.simulate("accel-gps", seed=4, settings={"scenario.duration": 40})
    imu, gps = sim.logs["imu"], sim.logs["gps"]
    free = "filter.gps_position_std,filter.gps_velocity_std"
    one = kalcal.fit("accel-gps", imu=imu, gps=gps, free=free, bootstrap=6, seed=2, threads=1, confidence=0.7)
    two = kalcal.fit("accel-gps", imu=imu, gps=gps, free=free, bootstrap=6, seed=2, threads=2, confidence=0.7)
    assert one.bootstrap.parameters == two.bootstrap.parameters
    position = one.bootstrap.parameters["filter.gps_position_std"]
    assert position.applicable and position.se > 0 and len(position.values) == 6
    assert one.to_dict()["bootstrap"]["replicates"] == 6
