"""When the latency's interval can be trusted: log L must be smooth at the interval's scale. On the
default (low-noise) scenario it is, and the interval covers a 20 ms latency; on rover-like logs it is
rough at the sample scale, and the fit says the latency is not resolved instead of giving an interval."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import stats

import kalcal
from kalcal.scenarios.accel_gps.latency_scan import ROUGH, UNRESOLVED, roughness

ROVER = Path(__file__).resolve().parents[2] / "examples" / "rover-like.toml"
DROP = stats.chi2.ppf(0.95, 1) / 2
LATENCY = 0.02
SEEDS = range(8)


def test_a_parabola_of_any_sharpness_and_a_smooth_bimodal_curve_are_smooth_and_sample_scale_bumps_are_not():
    grid = np.arange(-0.5, 0.5001, 0.0025)
    for curvature in (1e3, 1e6):  # a wide hill, and one that falls by more than the drop between neighbours
        assert roughness(grid, -curvature * (grid - 0.02) ** 2, DROP) < 1e-6
    bimodal = 5.0 * np.exp(-((grid + 0.05) / 0.03) ** 2) + 4.5 * np.exp(-((grid - 0.1) / 0.03) ** 2)
    assert roughness(grid, bimodal, DROP) < ROUGH * DROP
    bumps = -1e3 * grid**2 + np.repeat(np.random.default_rng(0).normal(0.0, 1.0, grid.size // 2 + 1), 2)[: grid.size]
    assert roughness(grid, bumps, DROP) > ROUGH * DROP


def latency_fit(seed, config=None, full=False):
    settings = {"scenario.duration": 60, "truth.gps_latency": LATENCY}
    sim = kalcal.simulate("accel-gps", seed=seed, config=config, settings=settings)
    extra = {"config": config, "settings": {"truth.gps_latency": 0}} if config else {}
    result = kalcal.fit("accel-gps", imu=sim.logs["imu"], gps=sim.logs["gps"], free="filter.gps_latency", **extra)
    return (result.parameters["filter.gps_latency"], result) if full else result.parameters["filter.gps_latency"]


def covers(p):
    return p.identified and p.ci_low is not None and p.ci_high is not None and p.ci_low <= LATENCY <= p.ci_high


@pytest.mark.slow
def test_on_the_default_scenario_the_latency_is_resolved_and_covered_at_the_intervals_rate():
    fits = [latency_fit(300 + seed) for seed in SEEDS]
    assert all(p.identified for p in fits), [p.note for p in fits]  # the rule does not flag a smooth log
    # one-sided binomial bound: at true coverage 0.95, fewer covering than this happens with probability < 0.001
    assert sum(covers(p) for p in fits) >= stats.binom.ppf(0.001, len(fits), 0.95)


@pytest.mark.slow
def test_on_rover_like_logs_a_resolved_latency_always_covers_and_all_eight_are_unresolved():
    fits = [latency_fit(100 + seed, ROVER) for seed in SEEDS]
    assert all(covers(p) for p in fits if p.identified), [(p.value, p.ci_low, p.ci_high) for p in fits]
    assert sum(p.note.startswith(UNRESOLVED) for p in fits) == 8  # docs/fit.md: all 8 of seeds 100-107
    assert all(p.value is None and p.ci_low is None for p in fits if not p.identified)


def test_a_default_log_resolves_a_20_ms_latency_though_its_hill_falls_by_more_than_the_drop_between_grid_points():
    p, result = latency_fit(300, full=True)
    assert covers(p) and not p.note.startswith(UNRESOLVED)
    curve = result.curves["filter.gps_latency"]
    value, loglik = np.array(curve["value"]), np.array(curve["loglik"])
    step = 0.0025  # the scan's grid at 200 Hz, whose points the curve holds
    after = loglik[np.argmin(np.abs(value - (p.ci_high - step)))], loglik[np.argmin(np.abs(value - p.ci_high))]
    assert abs(after[0] - after[1]) > DROP  # a sharp smooth hill: neighbouring grid points differ by more than 1.92


@pytest.mark.parametrize("gate", [None, 0.999])
def test_an_unresolved_latencys_fitted_filter_and_its_adequacy_use_the_input_latency(gate):
    from kalcal.scenarios.accel_gps.fit import fit_accel_gps
    from kalcal.scenarios import build_scenario

    from tests.fitting.fake_log import FakeLog

    key = "filter.gps_latency"
    knots = np.arange(-0.6, 0.6001, 0.005)  # a kink every 5 ms, as a noisy accelerometer's samples make
    bumps = np.random.default_rng(1).normal(0.0, 1.5, knots.size)
    log = FakeLog(lambda v: -1e3 * (v[key] - 0.03) ** 2 + np.interp(v[key], knots, bumps),
                  np.random.default_rng(0).standard_normal((500, 2)), {key: 0.0})
    result = fit_accel_gps(log, build_scenario("accel-gps", None, []), [key], gate=gate)
    p = result.parameters[key]
    assert not p.identified and p.value is None and p.note.startswith(UNRESOLVED)
    assert key not in log.calls[-1]  # the diagnostics' calibration: the input latency
    assert result.settings["filter"]["gps_latency"] == 0.0
    # nothing else free to refit: log L and AIC are those of the written point; the innovations (white,
    # unit) pass there, and the unresolved latency does not by itself make the fit inadequate
    assert result.loglik == log.loglik({}) and result.aic == -2.0 * result.loglik
    assert result.adequate
