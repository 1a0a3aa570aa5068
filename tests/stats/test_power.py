"""The checks' power from the exact analysis: alpha-level for a correct filter, and the brackets held to the
real checks' failure rates over seeded ensembles (Clopper-Pearson bounds at 99.9%)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import stats as sps

from kalcal.analysis.fixed_gain import analyze_problem, analyze_scenario
from kalcal.stats.suite import check_families, power_rows, problem_power
from kalcal.stats.power import DETECTION_POWER, MIN_N, N_CAP, detection_n, power_line, verdict_power
from kalcal.stats.sensitivity import detected_error, sensitivity, sensitivity_text
from kalcal.api.verification import MIN_REALIZATIONS
from kalcal.scenarios.model_file.model import load_model_file, parse_model
from kalcal.scenarios import build_scenario
from kalcal.montecarlo.accumulators import ensemble_statistics
from kalcal.montecarlo.engine import run_monte_carlo
from kalcal.montecarlo.scenarios import build_problem
from kalcal.stats.suite import run_checks

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
ALPHA = 0.01
#: a constant-velocity tracker over 10 updates; the truth's line is replaced per case
SMALL = """
name = "cv-small"
sample_period = 0.1
steps_per_update = 10
updates = 10
phi   = [[1.0, 0.1], [0.0, 1.0]]
gamma = [[0.005], [0.1]]
w     = [[0.0025]]
h     = [[1.0, 0.0]]
v     = [[4.0]]
x0    = [0.0, 10.0]
m0    = [[25.0, 0.0], [0.0, 1.0]]
[truth]
"""


def _overlaps(failures: int, trials: int, low: float, high: float) -> bool:
    ci = sps.binomtest(failures, trials).proportion_ci(confidence_level=0.999)
    return ci.low <= high and ci.high >= low


def _failures(problem, cause, n: int, seeds: range, name: str, part: str | None = None) -> int:
    """How many of the seeded ensembles of n realizations fail check ``name`` (or its part), by the real checks."""
    count = 0
    for seed in seeds:
        statistics = ensemble_statistics(run_monte_carlo(problem, n, seed).sums)
        checks = {c.name: c for c in run_checks(statistics, problem.info, 0.99, problem.expected_mean_error(), cause)}
        result = checks[name] if part is None else {p.name: p for p in checks[name].parts}[part]
        count += not result.passed
    return count


@pytest.mark.parametrize("scenario", ["accel-gps:discrete", "constant_velocity.toml"])
def test_correct_filter_power_is_alpha_level_and_not_detectable(scenario):
    """Truth equal to the filter: every check's power_high is its alpha (its parts' shares), nothing is detectable."""
    if scenario.endswith(".toml"):
        model = load_model_file(EXAMPLES / scenario)
    else:
        model = build_scenario("accel-gps", assignments=["scenario.truth=discrete"])
    rows = power_rows(analyze_scenario(model, budget=False), 300_000)
    for row in rows:
        share = ALPHA if row["part"] is None else ALPHA / 2
        assert row["power_low"] <= row["power_high"] <= share * (1 + 1e-6), row
        assert row["detectable"] is False and row["detection_n"] is None, row
    whole = verdict_power(rows)
    assert whole["power_high"] <= 5 * ALPHA * (1 + 1e-6) and not whole["detectable"]
    assert "not detected up to N = 1,000,000,000" in power_line(rows, 300_000)


def test_detection_n_is_the_smallest_n_reaching_the_power():
    problem, _ = build_problem(parse_model(SMALL + "w = [[0.01]]\n", "small.toml"))
    rows = power_rows(analyze_problem(problem, budget=False), 1000)
    families = {c.name: c for c in check_families(analyze_problem(problem, budget=False))}
    nees = families["covariance"].parts["centered_nees"]
    row = next(r for r in rows if (r["name"], r["part"]) == ("covariance", "centered_nees"))
    k = row["detection_n"]
    assert row["detectable"] and MIN_N < k < N_CAP
    assert nees.bracket(k)[0] >= DETECTION_POWER > nees.bracket(k - 1)[0]
    whole = next(r for r in rows if (r["name"], r["part"]) == ("covariance", None))
    parts = [r["detection_n"] for r in rows if r["name"] == "covariance" and r["part"] is not None]
    assert whole["detection_n"] == min(parts)
    assert MIN_N == MIN_REALIZATIONS
    assert detection_n(lambda n: 1.0) == MIN_N and detection_n(lambda n: 0.0) is None


@pytest.mark.parametrize(
    ("truth", "name"),
    [("w = [[0.01]]", "covariance"), ("v = [[6.0]]", "nis"), ("x0 = [1.0, 10.0]", "mean_error")],
)
def test_checks_fail_at_a_rate_inside_the_bracket(truth, name):
    """At the N where the bracket's conservative end puts the check's power at 0.5 and at 0.99, the real check
    fails 40 seeded ensembles at a rate whose 99.9% Clopper-Pearson interval meets the bracket."""
    problem, cause = build_problem(parse_model(SMALL + truth + "\n", "small.toml"))
    check = {c.name: c for c in check_families(analyze_problem(problem, budget=False))}[name]
    for target in (0.5, DETECTION_POWER):
        n = detection_n(lambda k: check.bracket(k)[0], target)
        low, high = check.bracket(n)
        assert low == pytest.approx(target, abs=0.01)
        failures = _failures(problem, cause, n, range(40), name)
        assert _overlaps(failures, 40, low, high), (target, n, failures, low, high)


#: truths and parts where the bracket at the N of power 0.5 is narrow (its ends within NARROW), so that a
#: failure rate off the bracket on either side is caught
NARROW_CASES = [
    ("x0 = [0.5, 10.0]\nm0 = [[1.0, 0.0], [0.0, 0.01]]", "mean_error", None),
    ("w = [[0.01]]", "covariance", "elements"),
    ("w = [[0.01]]", "covariance", "centered_nees"),
    ("m0 = [[100.0, 0.0], [0.0, 1.0]]", "orthogonality", None),
    ("x0 = [3.0, 10.0]", "nis", None),
]
NARROW = 0.2


@pytest.mark.parametrize(("truth", "name", "part"), NARROW_CASES)
def test_failure_rates_meet_a_narrow_bracket_from_both_sides(truth, name, part):
    """Where the bracket is at most NARROW wide (checked), the 99.9% Clopper-Pearson interval of 40 seeded
    ensembles' failure rate must meet it at the N of power 0.5 and 0.99: a rate too low or too high fails."""
    problem, cause = build_problem(parse_model(SMALL + truth + "\n", "small.toml"))
    check = {c.name: c for c in check_families(analyze_problem(problem, budget=False))}[name]
    family = check.parts[part]
    for target in (0.5, DETECTION_POWER):
        n = detection_n(lambda k: family.bracket(k)[0], target)
        low, high = family.bracket(n)
        assert low == pytest.approx(target, abs=0.01) and high - low <= NARROW, (target, n, low, high)
        failures = _failures(problem, cause, n, range(40), name, part)
        assert _overlaps(failures, 40, low, high), (target, n, failures, low, high)


def test_portmanteau_detects_the_colored_gps_error_the_pairs_miss():
    """The colored GPS error correlates every pair of position innovations a little: at N = 100 (10 s run)
    the portmanteau's power is above 0.9 and the pairs' at most 0.10, and 20 seeded ensembles agree; the
    portmanteau reaches 0.99 at about a ninth of the pairs' N. Every number docs/verification.md quotes is
    this test's computed value."""
    import math

    doc = " ".join((Path(__file__).resolve().parents[2] / "docs" / "verification.md").read_text(encoding="utf-8").split())
    model = load_model_file(EXAMPLES / "accel_gps_colored_gps.toml", ["model.updates=50"])
    problem, cause = build_problem(model)
    parts = {c.name: c for c in check_families(analyze_problem(problem, budget=False))}["residual_whiteness"].parts
    pairs, port = parts["pairs"].bracket(100), parts["portmanteau"].bracket(100)
    assert port[0] > 0.9 and pairs[1] < 0.1
    rows = {(r["name"], r["part"]): r for r in power_rows(analyze_problem(problem, budget=False), 100)}
    n_port, n_pairs = (rows[("residual_whiteness", part)]["detection_n"] for part in ("portmanteau", "pairs"))
    # each is where its conservative end first reaches 0.99 (power increasing in N)
    for family, k in ((parts["portmanteau"], n_port), (parts["pairs"], n_pairs)):
        assert family.bracket(k)[0] >= DETECTION_POWER > family.bracket(k - 1)[0]
    assert round(n_pairs / n_port) == 9 and "about a ninth of the pairs' N" in doc
    assert f"({n_port} against {n_pairs:,};" in doc
    port_text = f"{port[0]:.2f}–{port[1]:.2f}" if f"{port[0]:.2f}" != f"{port[1]:.2f}" else f"{port[0]:.2f}"
    assert f"at N = 100 the portmanteau's power is {port_text} and the pairs' at most {math.ceil(100 * pairs[1]) / 100:.2f};" in doc
    problem_30s, _ = build_problem(load_model_file(EXAMPLES / "accel_gps_colored_gps.toml"))
    rows_30s = power_rows(analyze_problem(problem_30s, budget=False), 20_000)
    assert power_line(rows_30s, 20_000).startswith(
        "power at N = 20,000: verdict 1.00 (detected from N = 100); mean_error 0.00–0.01, covariance 1.00, "
    )
    whole = {(r["name"], r["part"]): r for r in rows_30s}
    assert whole[("residual_whiteness", "portmanteau")]["detection_n"] == MIN_N  # power_low >= 0.99 at N = 100
    n_pairs_30s = whole[("residual_whiteness", "pairs")]["detection_n"]
    assert 500 < n_pairs_30s < 600
    assert f"reaches 0.99 only at N = {n_pairs_30s} (between 500 and 600)" in doc
    counts = {}
    for part, (low, high) in (("pairs", pairs), ("portmanteau", port)):
        counts[part] = _failures(problem, cause, 100, range(20), "residual_whiteness", part)
        assert _overlaps(counts[part], 20, low, high), (part, counts[part], low, high)
    assert counts == {"pairs": 0, "portmanteau": 18}  # as docs/verification.md quotes them
    assert f"20 seeded ensembles fail them {counts['portmanteau']} and {counts['pairs']} times" in doc


def test_verification_power_is_null_with_its_reason_for_scale_bias():
    problem, _ = build_problem(build_scenario("scale-bias"))
    rows, reason = problem_power(problem, 1000, 0.99)
    assert rows is None and "gains depend on the noisy readings: the measurement rows are data" in reason
    assert power_line(rows, 1000, reason).startswith("power: not computed (no exact analysis")
    from kalcal.api.verification import power_summary

    assert power_summary(problem, 1000, 0.99) == {"power": None, "power_reason": reason}  # summary.json's keys


def test_sensitivity_finds_the_smallest_detected_error():
    """For a correct filter, each setting's reported error is detected and one RESOLUTION step below is not."""
    from kalcal.stats import sensitivity as module

    model = load_model_file(EXAMPLES / "constant_velocity.toml")
    rows = sensitivity(model, 20_000)
    assert [r["setting"] for r in rows] == ["truth.w", "truth.v", "truth.m0"]
    scaled = module.noise_settings(model)
    for row in rows:
        up = row["increase"]
        assert up is not None and 0 < up < 0.2
        assert module._detects(scaled[row["setting"]](1 + up), 20_000, 0.99, "joseph")
        assert not module._detects(scaled[row["setting"]](1 + up / module.RESOLUTION), 20_000, 0.99, "joseph")
    assert ", ".join(sensitivity_text(row) for row in rows) == "w ±4.4%, v ±2.8%, m0 ±3.4%"  # as docs/analysis.md
    assert sensitivity_text({"setting": "truth.accel_noise_std", "increase": 0.03, "decrease": 0.031}) == "accel_noise_std ±3.1%"
    assert detected_error(lambda eps: eps > 0.3, 0.9) == pytest.approx(0.3, rel=module.RESOLUTION - 1)
    assert detected_error(lambda eps: False, 0.9) is None


def test_sensitivity_holds_the_filter_of_accel_gps():
    """Scaling a truth setting leaves the filter's (unset, so taken from the truth) where it was."""
    from kalcal.stats.sensitivity import noise_settings

    model = build_scenario("accel-gps", assignments=["scenario.truth=discrete"])
    scaled = noise_settings(model)["truth.accel_noise_std"](1.1)
    assert scaled.truth.accel_noise_std == pytest.approx(1.1 * model.truth.accel_noise_std)
    assert scaled.filter_settings.accel_noise_std == model.filter_settings.accel_noise_std
    assert np.isclose(scaled.filter_settings.gps_position_std, model.truth.gps_position_std)


def test_chi_square_part_without_spread_is_its_fixed_value():
    """A = 0 with a nonzero mean: every term is |mu|^2, so X = N m2 exactly, failing only outside the bounds."""
    from kalcal.stats.power import ChiSquareFamily

    zero = np.zeros(2)

    def family(m2):
        return ChiSquareFamily(zero, zero, np.full(2, m2), zero, 0, lambda n: (0.5 * n, 1.5 * n))

    assert family(1.0).bracket(1000) == (0.0, 0.0)  # X = 1000 inside [500, 1500]
    assert family(2.0).bracket(1000) == (1.0, 1.0)  # X = 2000 above
    assert family(0.25).bracket(1000) == (1.0, 1.0)  # X = 250 below
    assert family(0.0).bracket(1000) == (1.0, 1.0)  # X = 0 below a positive lower bound


def test_exact_prediction_computes_no_budget(monkeypatch):
    """The self-check's and the report's exact prediction needs only the moments: no error budget is run."""
    from kalcal.analysis import fixed_gain
    from kalcal.stats.self_check import exact_prediction

    def refuse(*args, **kwargs):
        raise AssertionError("the budget was computed")

    monkeypatch.setattr(fixed_gain, "error_budget", refuse)
    problem, _ = build_problem(parse_model(SMALL + "w = [[0.01]]\n", "small.toml"))
    assert exact_prediction(problem).available


def test_truth_equals_filter_only_where_it_does():
    """Equal for the correct examples; not for a mistuned one, a larger truth, nor a truth 1e-7 off in v, which
    no check detects up to N_CAP either: its line then says only that, not that no check can."""
    from kalcal.stats.power import truth_equals_filter

    assert truth_equals_filter(analyze_scenario(load_model_file(EXAMPLES / "constant_velocity.toml"), budget=False))
    assert truth_equals_filter(analyze_scenario(build_scenario("accel-gps", assignments=["scenario.truth=discrete"]), budget=False))
    for name in ("constant_velocity_mistuned.toml", "accel_gps_colored_gps.toml"):
        assert not truth_equals_filter(analyze_scenario(load_model_file(EXAMPLES / name), budget=False))
    near = analyze_scenario(load_model_file(EXAMPLES / "constant_velocity.toml", ["truth.v=[[4.0000004]]"]), budget=False)
    rows = power_rows(near, 300_000)
    assert not truth_equals_filter(near) and not verdict_power(rows)["detectable"]
    line = power_line(rows, 300_000, equal=False)
    assert "(not detected up to N = 1,000,000,000)" in line and "no check can detect" not in line
    assert "(not detected up to N = 1,000,000,000: no check can detect it (the truth equals the filter))" in power_line(
        rows, 300_000, equal=True
    )


def _probabilities_by_the_rule(family, n):
    """NormalFamily's P_i written out in full at every call: the normal law where a comparison has spread,
    the checks' rule where it has none (the reference for the family's precomputed, shortcut form)."""
    from scipy.special import ndtr

    a, v, d, c = family.mean, family.variance, family.scale, family.critical
    shift, edge = a * np.sqrt(float(n)), c * np.sqrt(np.maximum(d, 0.0))
    spread = np.sqrt(np.maximum(v, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        normal = ndtr((shift - edge) / spread) + ndtr((-shift - edge) / spread)
    fixed = np.where(np.abs(shift) > edge, 1.0, 0.0)
    fixed = np.where((d <= 0) & (a == 0), 0.0, fixed)
    out = np.where(spread > 0, normal, fixed)
    return np.minimum(1.0, np.where((d <= 0) & (v > 0), 1.0, out))


@pytest.mark.parametrize("with_degenerate", [False, True])
def test_normal_family_gives_the_rules_bits_at_every_n(with_degenerate):
    """Precomputed once and evaluated at many N (as the detection search does), the family's P_i are the
    bits of the rule evaluated afresh, with and without comparisons that have no spread or no standard error."""
    from kalcal.stats.power import NormalFamily

    rng = np.random.default_rng(7)
    mean, variance, scale = rng.normal(0, 0.05, 500), rng.uniform(0.5, 2.0, 500), rng.uniform(0.5, 2.0, 500)
    if with_degenerate:
        variance[:3], mean[:3] = 0.0, (0.0, 0.3, -0.01)
        scale[3:6], mean[3] = 0.0, 0.0
    family = NormalFamily(mean, variance, scale, 3.5)
    for n in (100, 5000, 10**6, 10**9, 5000):
        np.testing.assert_array_equal(family.probabilities(n), _probabilities_by_the_rule(family, n))
