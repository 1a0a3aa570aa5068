"""The nonlinear scenario's tolerance outcomes (within, outside, undecided), its power by simulation against
named alternatives, and the honesty of the effect sizes' intervals (their coverage over seeds against long-run
values known exactly). Fixed seeds; every bound from the binomial distribution."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import stats as sps

from kalcal.models.settings import SettingError
from kalcal.montecarlo.engine import run_monte_carlo
from kalcal.scenarios import load_code_model
from kalcal.scenarios.nonlinear.power import ALTERNATIVES, alternative_models, simulated_power
from kalcal.stats.distributions import binom_interval as clopper_pearson
from kalcal.stats.effects import (
    TOLERANCE_OUTCOMES,
    _make,
    overall_outcome,
    realizations_to_decide,
    tolerance_band,
    tolerance_outcome,
)

from .test_nonlinear_scenario import EXAMPLE, _cli, linear_model

# -- 1. tolerance outcomes --------------------------------------------------------------------------


def test_each_tolerance_outcome():
    band = tolerance_band("ratio", 0.1)  # [0.909, 1.111]
    assert tolerance_outcome(0.95, 1.05, band) == "within"
    assert tolerance_outcome(1.2, 1.3, band) == "outside"
    assert tolerance_outcome(0.5, 0.8, band) == "outside"
    assert tolerance_outcome(0.911, 1.201, band) == "undecided"  # N = 10^4 range-bearing EKF: not "fail"
    assert tolerance_outcome(0.8, 1.3, band) == "undecided"  # straddles both edges


def test_undecided_says_how_many_realizations_would_decide():
    """The case of the issue: NEES/d 1.056, CI [0.911, 1.201] at N = 10^4, band +-10 %."""
    n, value, half = 10_000, 1.056, 0.145
    band = tolerance_band("ratio", 0.1)
    more = realizations_to_decide(value, half, band, n)
    expected = n * (half / (band[1] - value)) ** 2
    assert more == int(np.ceil(expected)) and 60_000 < more < 80_000
    # the interval's half-width falls as 1/sqrt(N): at N' it clears the nearest edge, just below it not yet
    zq = sps.norm.isf(0.005)
    se = half / zq
    at = _make("nees_per_dim", None, value, se * np.sqrt(n / more), 1.0, "ratio", 0.1, 0.99, more)
    assert at.outcome == "within" and at.realizations_to_decide is None
    short = int(0.9 * more)
    before = _make("nees_per_dim", None, value, se * np.sqrt(n / short), 1.0, "ratio", 0.1, 0.99, short)
    assert before.outcome == "undecided" and before.realizations_to_decide >= more
    assert realizations_to_decide(band[1], half, band, n) is None  # on the edge: no N decides


def test_outcome_is_typed_and_consistent():
    e = _make("bias_sigma", "px", 0.0, 0.2, 0.0, "shift", 0.1, 0.99, 50)
    assert e.outcome == "undecided" and not e.within_tolerance and e.realizations == 50
    assert e.outcome in TOLERANCE_OUTCOMES
    with pytest.raises(ValueError, match="outcome"):
        type(e)(**{**e.as_dict(), "outcome": "maybe"})
    with pytest.raises(ValueError, match="within_tolerance"):
        type(e)(**{**e.as_dict(), "within_tolerance": True})
    within = _make("bias_sigma", "px", 0.0, 0.01, 0.0, "shift", 0.1, 0.99, 5000)
    outside = _make("bias_sigma", "px", 0.5, 0.01, 0.0, "shift", 0.1, 0.99, 5000)
    assert overall_outcome([within]) == "pass"
    assert overall_outcome([within, e]) == "undecided"
    assert overall_outcome([within, e, outside]) == "fail"


def test_a_short_run_of_a_correct_filter_is_undecided_not_failed():
    """The linear model's EKF is the Kalman filter (truth = filter): at N = 40 a band of +-5 % is too narrow for
    its intervals, which straddle the edges: undecided, with the realizations that would decide."""
    scenario = load_code_model(linear_model(), ["scenario.updates=10", "checks.tolerance=0.05"])
    problem = scenario.problem()
    run = run_monte_carlo(problem, 40, 5, workers=1)
    effects = problem.effect_sizes(run.sums, 0.99)
    nees = next(e for e in effects.overall if e.name == "nees_per_dim")
    assert nees.lower <= 1.0 <= nees.upper
    assert nees.outcome == "undecided" and nees.realizations_to_decide > 40
    assert effects.verdict() == "undecided"
    assert not any(e.outcome == "outside" for e in effects.overall)


# -- 2. power by simulation ---------------------------------------------------------------------------


def test_alternatives_are_what_they_say():
    base = linear_model()
    truth, belief = alternative_models(base, "R x 1.5")
    np.testing.assert_array_equal(truth.r, base.r * 1.5)
    assert belief is base
    truth, belief = alternative_models(base, "P x 0.8")
    assert truth is base
    np.testing.assert_array_equal(belief.p0, base.p0 * 0.8)
    np.testing.assert_array_equal(belief.q, base.q * 0.8)
    truth, belief = alternative_models(base, "bias 0.2 sigma")
    x = np.ones((3, 4))
    np.testing.assert_allclose(truth.measure(x) - base.measure(x), np.broadcast_to(0.2 * np.sqrt(np.diag(base.r)), (3, 2)))
    np.testing.assert_array_equal(truth.measurement_jacobian(x), base.measurement_jacobian(x))
    truth, belief = alternative_models(base, "null")
    assert truth is base and belief is base
    with pytest.raises(ValueError, match="alternative"):
        alternative_models(base, "Q x 2")


def test_clopper_pearson_interval():
    assert clopper_pearson(20, 20, 0.99) == (pytest.approx(0.005 ** (1 / 20)), 1.0)
    lo, hi = clopper_pearson(0, 20, 0.99)
    assert lo == 0.0 and hi == pytest.approx(1 - 0.005 ** (1 / 20))
    lo, hi = clopper_pearson(5, 50, 0.95)
    assert lo < 0.1 < hi


def test_r_x_1_5_nis_power_is_high_and_stated_with_its_interval():
    """The range-bearing EKF at N = 500, K = 20: the truth's R 1.5 times the filter's raises the mean NIS per
    measurement by about half of R's share of S. The NIS check rejects every one of 10 runs: the power by
    simulation is at least 0.59 at 99 % (Clopper–Pearson), and its tolerance verdict fails every run too."""
    scenario = load_code_model(str(EXAMPLE), ["scenario.updates=20"])
    power = simulated_power(scenario, 500, 11, 0.99, 10, workers=1)
    row = power.rate("R x 1.5", "nis")
    assert row.exact_rejections == 10 and row.exact_rate == 1.0
    assert row.exact_lower == pytest.approx(0.005 ** (1 / 10)) and row.exact_upper == 1.0
    assert row.tolerance_rejections == 10
    assert {r.alternative for r in power.rows} == set(ALTERNATIVES)
    document = power.as_dict()
    assert document["method"] == "by simulation" and "by simulation" in document["note"]


def _null_rejections(runs: int, seed: int) -> dict[str, int]:
    scenario = load_code_model(linear_model(), ["scenario.updates=10"])
    power = simulated_power(scenario, 300, seed, 0.99, runs, workers=1)
    return {r.check: r.exact_rejections for r in power.rows if r.alternative == "null"}


def _assert_null_rate(counts: dict[str, int], runs: int) -> None:
    # each exact check states a false-alarm rate of at most alpha = 0.01: its count over the runs is at most
    # Binomial(runs, 0.01), exceeded with probability below 0.001 per check (Bonferroni over the checks)
    limit = int(sps.binom.isf(0.001 / len(counts), runs, 0.01))
    assert counts and all(c <= limit for c in counts.values()), (counts, limit)


def test_null_rejection_rate_is_at_most_alpha():
    _assert_null_rate(_null_rejections(30, 3), 30)


@pytest.mark.slow
def test_null_rejection_rate_is_at_most_alpha_long():
    _assert_null_rate(_null_rejections(400, 4), 400)


def test_power_runs_setting():
    with pytest.raises(SettingError, match="checks.power_runs"):
        load_code_model(str(EXAMPLE), ["checks.power_runs=-1"])
    scenario = load_code_model(str(EXAMPLE), ["scenario.updates=5"])
    assert scenario.checks.power_runs == 0 and scenario.problem().simulated_power(100, 0, 0.99) is None


def test_cli_summary_and_report_carry_outcomes_and_power(tmp_path):
    out = tmp_path / "out"
    done = _cli(
        "verify", str(EXAMPLE), "-n", "300", "--out", str(out),
        "--set", "scenario.updates=10", "--set", "checks.power_runs=2",
    )
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    effects = summary["effect_sizes"]
    assert effects["verdict"] in ("pass", "fail", "undecided")
    for e in effects["overall"]:
        assert e["outcome"] in TOLERANCE_OUTCOMES and e["realizations"] == 300
        assert (e["realizations_to_decide"] is not None) <= (e["outcome"] == "undecided")
    covariance = next(t for t in summary["tests"] if t["name"] == "covariance")
    assert covariance["tolerance_outcome"] in ("pass", "fail", "undecided")
    power = summary["power_by_simulation"]
    assert power["method"] == "by simulation" and power["runs"] == 2 and power["realizations"] == 300
    assert {r["alternative"] for r in power["rows"]} == set(ALTERNATIVES)
    page = (out / "report.html").read_text()
    assert "Power by simulation" in page and "tolerance outcome" in page


# -- 3. the intervals' coverage -------------------------------------------------------------------------


def long_run_values(truth, belief, n_updates: int) -> tuple[float, np.ndarray]:
    """NEES/d and the variance ratio per state that a linear filter ``belief`` has against ``truth`` in the
    long run, exactly: the filter's own P_k by its Riccati recursion, the true error covariance Sigma_k by
    the same gains applied to the truth's Q and R (Joseph form), both from the prior; NEES_k = tr(P_k^-1
    Sigma_k), the variance ratio sum_k Sigma_ii,k / sum_k P_ii,k."""
    x = np.zeros((1, belief.state_dim))
    f = belief.transition_jacobian(x)[0]
    h = belief.measurement_jacobian(x)[0]
    p, sigma = np.asarray(belief.p0, float), np.asarray(truth.p0, float)
    eye = np.eye(belief.state_dim)
    nees, sig_diag, p_diag = [], [], []
    for _ in range(n_updates):
        p = f @ p @ f.T + belief.q
        sigma = f @ sigma @ f.T + truth.q
        s = h @ p @ h.T + belief.r
        gain = np.linalg.solve(s, h @ p).T  # P H^T S^-1 (S symmetric)
        a = eye - gain @ h
        p = a @ p @ a.T + gain @ belief.r @ gain.T
        sigma = a @ sigma @ a.T + gain @ truth.r @ gain.T
        nees.append(np.trace(np.linalg.solve(p, sigma)))
        sig_diag.append(np.diag(sigma))
        p_diag.append(np.diag(p))
    return float(np.mean(nees)) / belief.state_dim, np.sum(sig_diag, axis=0) / np.sum(p_diag, axis=0)


def _coverage(truth, belief, seeds: int, n: int, confidence: float) -> tuple[dict[str, int], tuple[float, np.ndarray]]:
    k = 10
    nees_true, ratio_true = long_run_values(truth, belief, k)
    problem = load_code_model((truth, belief), [f"scenario.updates={k}"]).problem()
    covered = {"nees_per_dim": 0, **{f"variance_ratio[{s}]": 0 for s in problem.info.state_names}}
    for seed in range(seeds):
        run = run_monte_carlo(problem, n, 1000 + seed, workers=1)
        effects = problem.effect_sizes(run.sums, confidence)
        for e in effects.overall:
            if e.name == "nees_per_dim":
                covered["nees_per_dim"] += int(e.lower <= nees_true <= e.upper)
            elif e.name == "variance_ratio":
                i = problem.info.state_names.index(e.element)
                covered[f"variance_ratio[{e.element}]"] += int(e.lower <= ratio_true[i] <= e.upper)
    return covered, (nees_true, ratio_true)


def _assert_coverage(covered: dict[str, int], seeds: int, confidence: float) -> None:
    # an honest interval covers its long-run value in Binomial(seeds, confidence) of the seeds: two-sided at
    # 0.001 overall (Bonferroni over the effects)
    alpha = 0.001 / len(covered)
    lo, hi = sps.binom.ppf(alpha / 2, seeds, confidence), sps.binom.isf(alpha / 2, seeds, confidence)
    assert all(lo <= c <= hi for c in covered.values()), (covered, lo, hi)


def test_long_run_values_of_a_correct_filter_are_one_and_of_a_mistuned_one_are_not():
    nees, ratio = long_run_values(linear_model(), linear_model(), 10)
    assert nees == pytest.approx(1.0, abs=1e-12) and np.allclose(ratio, 1.0, atol=1e-12)
    nees, ratio = long_run_values(linear_model(), linear_model(4.0), 10)
    assert nees < 0.8 and np.all(ratio < 1.0)


@pytest.mark.parametrize("r_scale", [1.0, 4.0], ids=["correct", "mistuned-R-x4"])
def test_intervals_cover_the_long_run_value_at_their_rate(r_scale):
    """80 seeds at N = 300: each interval at 90 % covers its exact long-run value in 80 x 0.9 of the seeds
    within the binomial bound (1 exactly for the correct filter, the Riccati value for the mistuned one)."""
    covered, _ = _coverage(linear_model(), linear_model(r_scale), 80, 300, 0.9)
    _assert_coverage(covered, 80, 0.9)


@pytest.mark.slow
@pytest.mark.parametrize("r_scale", [1.0, 4.0], ids=["correct", "mistuned-R-x4"])
def test_intervals_cover_the_long_run_value_at_their_rate_long(r_scale):
    covered, _ = _coverage(linear_model(), linear_model(r_scale), 1000, 300, 0.9)
    _assert_coverage(covered, 1000, 0.9)
