"""The bench's self-check: the ensemble against the exact analysis, agreeing for correct engines, failing
for a wrong one, at most alpha false alarms, recorded in summary.json apart from the verdict.

Fixed seeds throughout; every bound is the self-check's own (Bonferroni over its comparisons) or a
binomial quantile, none tuned.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from scipy import stats as sps

from kalcal.analysis.fixed_gain import analyze_problem
from kalcal.stats.power import product_variance
from kalcal.scenarios.accel_gps.settings import AccelGpsScenario
from kalcal.models.config import apply_settings
from kalcal.scenarios.model_file.model import load_model_file
from kalcal.montecarlo.accumulators import ensemble_statistics
from kalcal.montecarlo.engine import run_monte_carlo
from kalcal.montecarlo.scenarios import build_problem
from kalcal.stats.bounds import normal_bound
from kalcal.stats.self_check import (
    SELF_CHECK_PARTS,
    exact_prediction,
    self_check,
    self_check_line,
    variance_ratio_band,
    variance_scores,
)

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
N = 2000
SHORT = {"scenario.duration": 6}
TRUTHS = {
    "correct": SHORT,
    "mistuned": {**SHORT, "truth.accel_noise_std": 0.05, "filter.accel_noise_std": 0.02, "truth.gps_position_std": 2.0},
    "drifting bias": {**SHORT, "truth.bias_walk_std": 5e-3, "filter.bias_walk_std": 0.0},
}


def _problem(name):
    if name == "colored gps":
        scenario = load_model_file(EXAMPLES / "accel_gps_colored_gps.toml")
    else:
        scenario = apply_settings(AccelGpsScenario(), TRUTHS[name])
    return build_problem(scenario, residual_pairs=False)[0]


def _run(problem, n=N, seed=7, engine="exact"):
    return ensemble_statistics(run_monte_carlo(problem, n, seed=seed, engine=engine, workers=1).sums)


@pytest.mark.parametrize("name", [*TRUTHS, "colored gps"])
def test_the_ensemble_agrees_with_the_exact_analysis(name):
    problem = _problem(name)
    exact = exact_prediction(problem)
    result = self_check(_run(problem), exact, 0.99, problem.info)
    k, d = exact.error_cov.shape[:2]
    assert result.agrees is True, result.detail
    p = exact.mean_residual.shape[1]
    assert result.comparisons == 2 * k * d + k * d * d + k * p  # mean, variance, E[e xhat^T], mean innovation
    parts = {part.name: part for part in result.parts}
    assert [parts[name].comparisons for name in SELF_CHECK_PARTS] == [k * d, k * d, k * d * d, k * p]
    for part in result.parts:  # each part at alpha / 4 over its own comparisons
        assert part.upper == pytest.approx(normal_bound(0.99, len(SELF_CHECK_PARTS) * part.comparisons), rel=1e-12)
    decisive = min(result.parts, key=lambda part: part.pvalue)
    assert result.bound == decisive.upper and result.statistic == decisive.statistic
    assert abs(result.statistic) <= result.bound and result.pvalue >= 0.01
    assert [part.name for part in result.parts] == list(SELF_CHECK_PARTS)
    assert result.reason is None and result.detail.startswith("The ensemble agrees")
    # the detail's "largest |z|" is the largest over every part, with its part named
    largest = max(result.parts, key=lambda part: abs(part.statistic))
    assert f"largest |z| = {abs(largest.statistic):.3g} (" in result.detail
    assert f"; {largest.name}) within ±{largest.upper:.3g}" in result.detail
    if largest is not decisive:
        assert f"the smallest p-value is {decisive.name}'s, |z| = {abs(decisive.statistic):.3g}" in result.detail
    if name == "colored gps":  # the report's 150 updates and 3 states: the bound docs/verification.md quotes
        assert (k, d, p) == (150, 3, 2)
        assert [round(parts[name].upper, 2) for name in SELF_CHECK_PARTS] == [4.54, 4.54, 4.77, 4.46]


def test_the_per_sample_engine_agrees_with_the_same_analysis():
    """The sampled engine simulates the truth whose law the exact engine samples: one analysis predicts both."""
    problem = _problem("drifting bias")
    result = self_check(_run(problem, engine="sampled"), exact_prediction(problem), 0.99, problem.info)
    assert result.agrees is True, result.detail


def test_the_mistuned_filter_fails_its_checks_while_the_bench_agrees():
    """The self-check is apart from the verdict: theory says the filter is wrong, and the engine agrees with theory."""
    problem = _problem("colored gps")
    exact = analyze_problem(problem, pairs=False)
    var, filt = np.diagonal(exact.moments.error_cov, axis1=1, axis2=2), np.diagonal(exact.filter_cov, axis1=1, axis2=2)
    assert np.max(var / filt) > 2  # the truth's colored GPS error: far worse than the filter believes
    assert self_check(_run(problem), exact_prediction(problem), 0.99, problem.info).agrees


def test_a_wrong_engine_is_detected():
    """An ensemble whose covariance is 1.2 times the truth's, or whose mean is off by 6 standard errors."""
    problem = _problem("correct")
    exact = exact_prediction(problem)
    n = 5000
    stats = _run(problem, n)
    good = self_check(stats, exact, 0.99, problem.info)
    assert good.agrees
    # computed, not hoped: at this N a 20 % variance excess sits beyond the bound by more than 4 sd of z
    assert variance_scores(np.array([1.2]), n)[0] > good.bound + 4.0
    wide = self_check(dataclasses.replace(stats, error_cov=1.2 * stats.error_cov), exact, 0.99, problem.info)
    assert wide.agrees is False and wide.pvalue < 0.01
    assert {part.name: part.passed for part in wide.parts} == {
        "mean_error": True, "error_variance": False, "error_estimate": True, "residual_mean": True
    }
    assert wide.detail.startswith("The ensemble departs") and "variance of" in wide.detail
    sd = np.sqrt(np.diagonal(exact.error_cov, axis1=1, axis2=2) / n)
    shifted = self_check(dataclasses.replace(stats, mean_error=stats.mean_error + 6.0 * sd), exact, 0.99, problem.info)
    assert shifted.agrees is False
    assert {part.name: part.passed for part in shifted.parts} == {
        "mean_error": False, "error_variance": True, "error_estimate": True, "residual_mean": True
    }
    # the other sums: E[e xhat^T] off by 6 of its standard errors, the mean innovation likewise
    mu_e, mu_x = exact.mean_error[:, :, None], exact.mean_estimate[:, None, :]
    var_x = np.diagonal(exact.estimate_cov, axis1=1, axis2=2)[:, None, :]
    var_e = np.diagonal(exact.error_cov, axis1=1, axis2=2)[:, :, None]
    se = np.sqrt(product_variance(mu_e, mu_x, var_e, var_x, exact.error_estimate - mu_e * mu_x) / n)
    moved = self_check(dataclasses.replace(stats, error_estimate=stats.error_estimate + 6.0 * se), exact, 0.99, problem.info)
    assert [part.name for part in moved.parts if not part.passed] == ["error_estimate"] and not moved.agrees
    assert "E[e x̂ᵀ] of" in moved.detail
    se_r = np.sqrt(np.diagonal(exact.residual_cov, axis1=1, axis2=2) / n)
    moved = self_check(dataclasses.replace(stats, mean_residual=stats.mean_residual + 6.0 * se_r), exact, 0.99, problem.info)
    assert [part.name for part in moved.parts if not part.passed] == ["residual_mean"] and not moved.agrees
    assert "mean innovation of" in moved.detail


def test_a_correct_engine_disagrees_at_most_at_the_rate_alpha():
    """400 seeded ensembles of N = 100 (the smallest verify allows), confidence 0.9: the disagreements are
    at most alpha's binomial upper quantile (1e-4), so the chi-square scores hold at small N."""
    problem = build_problem(load_model_file(EXAMPLES / "constant_velocity.toml", ["model.updates=3"]), residual_pairs=False)[0]
    exact = exact_prediction(problem)
    runs = 400
    failures = sum(not self_check(_run(problem, 100, seed), exact, 0.9, problem.info).agrees for seed in range(runs))
    assert failures <= sps.binom.isf(1e-4, runs, 0.1)


def test_variance_scores_are_the_chi_square_tails_and_the_figure_band_is_the_bound():
    count, comparisons, confidence = 150, 40, 0.99
    low, high = variance_ratio_band(confidence, comparisons, count)
    bound = normal_bound(confidence, len(SELF_CHECK_PARTS) * comparisons)
    np.testing.assert_allclose(np.abs(variance_scores(np.array([low, high]), count)), bound, rtol=1e-8)
    assert variance_scores(np.array([1.0]), count)[0] == 0.0
    # one sided tail: P(chi2 > (N - 1) r) = Phi(-z)
    z = variance_scores(np.array([1.3]), count)[0]
    assert sps.norm.sf(z) == pytest.approx(sps.chi2.sf(1.3 * (count - 1), count - 1), rel=1e-9)


def test_the_exact_mean_error_is_the_expected_mean_error():
    """stats.nc's expected_mean_error is the exact mean error that the self-check uses (to rounding)."""
    problem = build_problem(apply_settings(AccelGpsScenario(), {**SHORT, "filter.position0_mean": 2.0}))[0]
    expected = problem.expected_mean_error()
    np.testing.assert_allclose(exact_prediction(problem).mean_error, expected, rtol=0, atol=1e-12 * np.max(np.abs(expected)))


def test_summary_records_the_self_check_and_the_exact_final_covariance(tmp_path):
    import kalcal

    result = kalcal.verify("accel-gps", 1000, seed=3, settings=SHORT, long_run=0, out=tmp_path / "run")
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    check = summary["self_check"]
    assert set(check) == {"statistic", "bound", "p_value", "agrees", "confidence", "comparisons", "parts", "detail", "reason"}
    assert check["agrees"] is True and check["confidence"] == 0.99 and check["reason"] is None
    assert check == json.loads(json.dumps(result.self_check.as_dict()))
    assert [part["name"] for part in check["parts"]] == list(SELF_CHECK_PARTS)
    problem = build_problem(apply_settings(AccelGpsScenario(), SHORT))[0]
    exact = exact_prediction(problem)
    np.testing.assert_allclose(summary["final"]["exact_error_covariance"], exact.error_cov[-1], rtol=1e-12)
    np.testing.assert_allclose(summary["final"]["exact_mean_error"], exact.mean_error[-1], rtol=1e-12, atol=1e-15)
    # apart from the verdict: a self-check that disagrees would not change it either
    assert summary["verdict"] == ("pass" if all(t["passed"] for t in summary["tests"]) else "fail")
    assert "self_check" not in [t["name"] for t in summary["tests"]]
    assert self_check_line(check).startswith("self-check of the bench (ensemble against the exact analysis; not in the verdict): agrees")


def _cli(*args):
    from typer.testing import CliRunner

    from kalcal.cli import app

    result = CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)
    assert result.exit_code == 0, result.output + result.stderr
    return result.stdout


def test_verify_prints_the_self_check_line(tmp_path):
    out = tmp_path / "run"
    stdout = _cli("verify", "-n", 300, "--no-report", "--long-run", 0, "--set", "scenario.duration=2", "--out", out)
    summary = json.loads((out / "summary.json").read_text())
    assert self_check_line(summary["self_check"]) in stdout.splitlines()
    # a PASS is about the filter on synthetic motion, not a log: the console says so, pointing to fit
    from kalcal.reporting.text import scope_statement

    assert scope_statement(summary) in stdout.splitlines()


def test_scale_bias_says_why_there_is_no_self_check(tmp_path):
    out = tmp_path / "run"
    stdout = _cli("verify", "scale-bias", "-n", 100, "--set", "scenario.duration=10", "--out", out)
    summary = json.loads((out / "summary.json").read_text())
    check = summary["self_check"]
    assert check["agrees"] is None and check["statistic"] is None and check["bound"] is None and check["parts"] == []
    assert "gains depend on the noisy readings" in check["reason"]
    assert check["detail"] == f"No self-check: {check['reason']}."
    assert summary["final"]["exact_error_covariance"] is None and summary["final"]["exact_mean_error"] is None
    assert self_check_line(check).endswith(f": none ({check['reason']})")
    assert self_check_line(check) in stdout.splitlines()
    page = (out / "report.html").read_text(encoding="utf-8")
    assert 'data-file="figures/sigma_exact.png"' not in page
    assert "gains depend on the noisy readings" in page and "Self-check of the bench" in page
    assert "exact σ = √P_true,ii" not in page


def test_the_cli_line_for_each_outcome():
    lead = "self-check of the bench (ensemble against the exact analysis; not in the verdict)"
    base = {"statistic": -5.123, "bound": 4.4, "p_value": 1e-4, "reason": None}
    # a summary without its parts: the statistic is named for what it is, the deciding part's
    assert self_check_line({**base, "agrees": False}) == (
        f"{lead}: DISAGREES, |z| 5.12 of the part with the smallest p-value against ±4.4, p = 0.0001"
    )
    assert self_check_line({**base, "agrees": False, "statistic": None, "p_value": None}).endswith(
        "|z| nan of the part with the smallest p-value against ±4.4, p = nan"
    )
    assert self_check_line(None) == f"{lead}: not recorded"


def _part(name, statistic, pvalue, bound, comparisons):
    from kalcal.stats.results import CheckPart

    share = 0.01 / 4
    return CheckPart(name, statistic, pvalue, -bound, bound, 1 - share, share, comparisons, pvalue >= share).as_dict()


def test_the_line_prints_the_largest_z_not_the_deciding_parts():
    """Parts of different sizes: the part with the smallest p-value (|z| 2.29 of 150 comparisons) is not the
    one with the largest |z| (3.14 of 13,500). The line prints the largest as the largest, and the deciding
    part's apart (the line printed 'largest |z| 2.29' for this run)."""
    lead = "self-check of the bench (ensemble against the exact analysis; not in the verdict)"
    parts = [_part("mean_error", 2.29, 0.33, 3.9, 150), _part("error_estimate", 3.14, 0.9, 4.6, 13_500)]
    document = {"statistic": 2.29, "bound": 3.9, "p_value": 1.0, "agrees": True, "reason": None, "parts": parts}
    line = self_check_line(document)
    assert line == (
        f"{lead}: agrees, largest |z| 3.14 (error_estimate) against ±4.6; smallest p-value: |z| 2.29 (mean_error) "
        "against ±3.9, p = 1"
    )
    same = {**document, "parts": [parts[1]], "statistic": 3.14, "bound": 4.6}
    assert self_check_line(same) == f"{lead}: agrees, largest |z| 3.14 (error_estimate) against ±4.6, p = 1"


def test_a_rounding_level_variance_is_left_out_not_a_disagreement():
    """A state whose exact variance is rounding-level (1e-14 of the largest) and whose ensemble variance is 0
    is no comparison: the self-check agrees over the other states' 2 K (d - 1) comparisons."""
    from kalcal.stats.self_check import VARIANCE_RTOL, compared_states

    problem = _problem("correct")
    exact = exact_prediction(problem)
    stats = _run(problem, 500)
    k, d = exact.mean_error.shape
    cov = exact.error_cov.copy()
    largest = np.max(np.diagonal(cov, axis1=1, axis2=2), axis=1)
    cov[:, -1, :] = cov[:, :, -1] = 0.0
    cov[:, -1, -1] = 1e-14 * largest
    ens_cov, ens_mean = stats.error_cov.copy(), stats.mean_error.copy()
    ens_cov[:, -1, :] = ens_cov[:, :, -1] = 0.0
    ens_mean[:, -1] = exact.mean_error[:, -1] + 1e-9
    # a certain e_last is its mean, so E[e_last xhat^T] = m_last E[xhat]^T, and the ensemble's m_last xbar^T
    exact_ex, ens_ex = exact.error_estimate.copy(), stats.error_estimate.copy()
    exact_ex[:, -1, :] = exact.mean_error[:, -1, None] * exact.mean_estimate
    ens_ex[:, -1, :] = ens_mean[:, -1, None] * stats.mean_estimate
    assert 1e-14 < VARIANCE_RTOL
    assert not compared_states(cov)[:, -1].any() and compared_states(cov)[:, :-1].all()
    result = self_check(
        dataclasses.replace(stats, error_cov=ens_cov, mean_error=ens_mean, error_estimate=ens_ex),
        dataclasses.replace(exact, error_cov=cov, error_estimate=exact_ex),
        0.99,
        problem.info,
    )
    parts = {part.name: part.comparisons for part in result.parts}
    assert result.agrees is True and parts["mean_error"] == parts["error_variance"] == k * (d - 1)
    # the certain state's row of E[e xhat^T] stays where its mean makes the product random (m_last^2 Var(xhat))
    assert k * (d - 1) * d <= parts["error_estimate"] <= k * d * d
    wide = self_check(dataclasses.replace(stats, error_cov=2.0 * stats.error_cov), exact, 0.99, problem.info)
    assert wide.agrees is False and "so the checks built on them cannot be trusted" in wide.detail


def test_the_figure_band_uses_the_self_checks_comparisons(monkeypatch, tmp_path):
    """plot_sigma_exact's band is variance_ratio_band at the self-check's count (states of zero variance out)."""
    from kalcal.plots import ensemble
    from kalcal.stats.dataset import statistics_dataset

    problem = _problem("correct")
    stats = _run(problem, 200)
    exact = exact_prediction(problem)
    cov = exact.error_cov.copy()
    cov[:, -1, :] = cov[:, :, -1] = 0.0
    seen = []
    monkeypatch.setattr(ensemble, "variance_ratio_band", lambda c, m, n: seen.append(m) or variance_ratio_band(c, m, n))
    attrs = {"scenario": problem.info.scenario, "seed": 1, "engine": "exact", "confidence": 0.99}
    dataset = statistics_dataset(stats, problem.info, problem.expected_mean_error(), attrs)
    ensemble.plot_sigma_exact(dataset, cov, tmp_path / "sigma.png")
    result = self_check(stats, dataclasses.replace(exact, error_cov=cov), 0.99, problem.info)
    variance_part = next(part for part in result.parts if part.name == "error_variance")
    assert seen == [variance_part.comparisons] and seen[0] == exact.mean_error.size - exact.mean_error.shape[0]
