"""The page's answer: the verdict's sentence, a line per check and the figures that show it, read from
the checks' causes in summary.json (built here as summary.json holds them, and from real runs)."""

import pytest

import kalcal
from kalcal.reporting.answer import UNNAMED_MODEL_ERROR, answer, lead_figures

EULER = "the euler integration of the accelerometer against the analytic truth"


def _check(name, passed, explained_by=None, direction=None, pvalue=None, reason="why"):
    return {
        "name": name,
        "passed": passed,
        "pvalue": (0.5 if passed else 1e-9) if pvalue is None else pvalue,
        "cause": {
            "explained_by": None if passed else explained_by,
            "direction": None if passed else direction,
            "reason": None if passed else reason,
        },
    }


def _summary(*tests, cause=EULER, **extra):
    return {"tests": list(tests), "confidence": 0.99, "model_error": {"cause": cause}} | extra


PASSED = [_check(name, True) for name in ("covariance", "orthogonality", "residual_whiteness", "nis")]


def test_every_check_passed():
    result = answer(_summary(_check("mean_error", True), *PASSED))
    assert (result.verdict, result.kind) == ("pass", "pass")
    assert result.sentence.startswith("Passes: all 5 checks lie within their bounds")
    assert [line.cause for line in result.checks] == ["within its bounds"] * 5
    assert all(line.root is None for line in result.checks)
    assert result.figures[:3] == ("mean_error", "nees", "nis")  # no model-error figure without a failure


def test_failures_rooted_in_the_model_error_say_it_removed_every_check_passes():
    """The default run: mean_error explained by the model error, the raw-moment checks by the mean error."""
    tests = [
        _check("mean_error", False, "model_error"),
        _check("covariance", True),
        _check("orthogonality", False, "mean_error"),
        _check("residual_whiteness", False, "mean_error", pvalue=0.0),
        _check("nis", False, "mean_error"),
    ]
    result = answer(_summary(*tests))
    assert (result.verdict, result.kind) == ("fail", "explained")
    assert result.sentence == (
        f"Fails only through the known model error of {EULER}: with it removed every check passes "
        "(4 of 5 checks fail)."
    )
    roots = {line.name: line.root for line in result.checks}
    assert roots == {"mean_error": "model_error", "covariance": None, "orthogonality": "model_error",
                     "residual_whiteness": "model_error", "nis": "model_error"}
    assert result.checks[0].cause == "the known model error: with it removed, within its bounds"
    assert result.checks[2].cause.startswith("the known model error (its mean): centered on the means")
    assert result.checks[3].pvalue == "0"
    assert result.figures[:4] == ("mean_error", "model_error", "nees", "nis")


def test_the_model_error_is_named_from_the_summary_never_written_in():
    tests = [_check("mean_error", False, "model_error"), *PASSED]
    other = answer(_summary(*tests, cause="the filter's prior mean differing from the truth's."))
    assert "known model error of the filter's prior mean differing from the truth's: with it removed" in other.sentence
    assert "1 of 5 checks fails" in other.sentence and "euler" not in other.sentence
    assert f"known model error of {UNNAMED_MODEL_ERROR}:" in answer(_summary(*tests, cause="")).sentence


def test_a_mean_error_the_model_does_not_account_for_is_not_the_model_error():
    """Centered on the means the NIS passes, but the mean error itself is not the predicted one."""
    tests = [_check("mean_error", False, None), _check("covariance", True), _check("orthogonality", True),
             _check("residual_whiteness", True), _check("nis", False, "mean_error")]
    result = answer(_summary(*tests))
    assert result.kind == "unexplained"
    assert result.sentence == (
        "Fails (2 of 5 checks fail): mean_error and nis are not accounted for by a known cause "
        "(nis only through a nonzero mean error: see mean_error)."
    )
    assert [line.root for line in result.checks] == [None, None, None, None, "mean_error"]
    assert result.checks[0].cause == "not identified (see What failed)"
    assert "removed every check passes" not in result.sentence


def test_unexplained_failures_name_their_direction_and_what_is_accounted_for():
    tests = [
        _check("mean_error", False, "model_error"),
        _check("covariance", False, direction="overconfident"),
        _check("orthogonality", False, "mean_error"),
        _check("residual_whiteness", False, None),
        _check("nis", False, direction="overconfident"),
    ]
    result = answer(_summary(*tests))
    assert (result.verdict, result.kind) == ("fail", "unexplained")
    assert result.sentence == (
        "Fails (5 of 5 checks fail): covariance, residual_whiteness and nis are not accounted for by a known "
        "cause; covariance and nis find the filter overconfident: the actual spread is larger than the "
        f"filter's P; mean_error and orthogonality are accounted for by the known model error of {EULER}."
    )
    assert result.checks[1].cause == "overconfident: the actual spread is larger than the filter's P"
    assert result.checks[3].cause == "not identified (see What failed)"
    # the failures nothing accounts for lead the figures, after the model error's
    assert result.figures[:5] == ("mean_error", "model_error", "nees", "residual_correlation", "nis")


def test_one_underconfident_check():
    tests = [_check("mean_error", True), _check("covariance", False, direction="underconfident"), *PASSED[1:]]
    result = answer(_summary(*tests, cause=""))
    assert result.sentence == (
        "Fails (1 of 5 checks fails): covariance is not accounted for by a known cause; covariance finds "
        "the filter underconfident: the actual spread is smaller than the filter's P."
    )
    assert result.figures[0] == "nees"


def test_a_false_alarm():
    tests = [_check("mean_error", True), *PASSED[:3], _check("nis", False, "false_alarm")]
    result = answer(_summary(*tests))
    assert (result.verdict, result.kind) == ("fail", "explained")
    assert result.sentence.startswith("Fails by a false alarm (1 of 5 checks fails): the truth equals the filter")
    assert "at most 1%" in result.sentence and "model error" not in result.sentence
    assert result.checks[4].cause == "a false alarm: the truth equals the filter"
    assert result.figures[0] == "nis"


def test_pvalues_as_the_page_writes_them():
    tests = [_check("mean_error", False, "model_error", pvalue=1.234567e-5), _check("nis", True, pvalue=None)]
    tests[1]["pvalue"] = None
    lines = answer(_summary(*tests)).checks
    assert [line.pvalue for line in lines] == ["1.23e-05", "—"]
    nan = answer(_summary(*tests, nonfinite={"fields": {"tests.pvalue": 1}})).checks
    assert nan[1].pvalue == "NaN"


def test_lead_figures_keeps_those_drawn_in_order_up_to_four():
    wanted = ("mean_error", "model_error", "nees", "nis", "variance_diagonal")
    assert lead_figures(wanted, ["nis", "nees", "mean_error", "variance_diagonal", "state_position"]) == [
        "mean_error", "nees", "nis", "variance_diagonal"
    ]
    assert lead_figures(wanted, ["nis", "model_error", "nees", "mean_error", "variance_diagonal"]) == list(wanted[:4])
    assert lead_figures(wanted, []) == []


# real runs, their causes as the checks computed them (summary.json's content): short, the answers robust
# to the seed (the effects are tens of standard errors at this N)
@pytest.mark.parametrize(
    "settings, kind, words",
    [
        # the default scenario (Euler against the analytic truth), shorter
        ({"scenario.duration": 6}, "explained", f"Fails only through the known model error of {EULER}"),
        ({"scenario.duration": 6, "scenario.integration": "trapezoid"}, "pass", "Passes: all 6 checks"),
        # a filter whose GPS velocity noise is half the truth's: its covariance and NIS overconfident
        (
            {"scenario.duration": 6, "scenario.integration": "trapezoid", "filter.gps_velocity_std": 0.02},
            "unexplained",
            "covariance and nis find the filter overconfident",
        ),
    ],
)
def test_the_answer_of_a_real_run(settings, kind, words):
    summary = kalcal.verify("accel-gps", n=5000, seed=3, settings=settings, long_run=0).to_dict()
    result = answer(summary)
    assert result.kind == kind and words in result.sentence, result.sentence
    assert [line.passed for line in result.checks] == [t["passed"] for t in summary["tests"]]


def _effect(name, outcome, decide=None):
    return {"name": name, "outcome": outcome, "realizations_to_decide": decide}


def _tolerant(check, outcome, *effects):
    return check | {"tolerance_outcome": outcome, "effect_sizes": list(effects)}


def _nonlinear_summary(*tests, verdict="undecided", n=20_000):
    return _summary(*tests, cause="", realizations=n, effect_sizes={"tolerance": 0.1, "verdict": verdict, "overall": []})


def test_a_nonlinear_run_says_the_exact_tests_and_the_tolerance_outcomes():
    """range_bearing.py at N = 20,000: every exact test fails (an EKF's P is a linearization's), while the
    effects are within the band or undecided; the sentence leads with both, never with the exact tests alone."""
    tests = [
        _tolerant(_check("mean_error", False), "pass", _effect("bias_sigma", "within")),
        _tolerant(_check("covariance", False, direction="overconfident"), "undecided",
                  _effect("nees_per_dim", "undecided", 2_365_404), _effect("variance_ratio", "undecided", 7_137_005),
                  _effect("variance_ratio", "within")),
        _check("orthogonality", False) | {"tolerance_outcome": None, "effect_sizes": []},
        _tolerant(_check("residual_whiteness", False), "pass", _effect("whiteness_lag1", "within")),
        _tolerant(_check("nis", False, direction="overconfident"), "undecided", _effect("nis_per_dim", "undecided", 2_622_404)),
    ]
    result = answer(_nonlinear_summary(*tests))
    assert (result.verdict, result.tolerance) == ("fail", "undecided")
    assert result.sentence.startswith("Fails the exact tests (5 of 5 checks fail), as a nonlinear model's approximate filter")
    assert "the tolerance verdict (band 0.1) is undecided: mean_error and residual_whiteness within the band" in result.sentence
    # the slowest undecided effect sets the realizations that decide them all
    assert "covariance and nis undecided (about 7,137,005 realizations would decide them" in result.sentence
    assert "this run has 20,000); orthogonality has no effect size" in result.sentence and "orthogonality has no effect size" in result.sentence
    # the exact tests' causes still follow
    assert "covariance and nis find the filter overconfident" in result.sentence


def test_a_nonlinear_run_outside_its_band_and_one_that_passes():
    outside = [
        _tolerant(_check("mean_error", False), "fail", _effect("bias_sigma", "outside")),
        _tolerant(_check("covariance", False), "pass", _effect("nees_per_dim", "within")),
    ]
    result = answer(_nonlinear_summary(*outside, verdict="fail"))
    assert result.tolerance == "fail"
    assert "is out of tolerance: covariance within the band; mean_error outside it" in result.sentence
    passing = [_tolerant(_check("mean_error", True), "pass", _effect("bias_sigma", "within")),
               _tolerant(_check("nis", True), "pass", _effect("nis_per_dim", "within"))]
    result = answer(_nonlinear_summary(*passing, verdict="pass"))
    assert result.kind == "pass" and result.tolerance == "pass"
    assert result.sentence == (
        "Passes: all 2 checks lie within their bounds, so this ensemble shows no departure of the filter from its "
        "own settings; the tolerance verdict (band 0.1) is within tolerance: mean_error and nis within the band."
    )
    # a linear run keeps no effect sizes: its sentence is the exact tests' alone
    assert answer(_summary(_check("mean_error", True))).tolerance is None


def test_the_answer_of_a_real_nonlinear_run():
    """The example model written as code: each check's tolerance outcome is in the sentence, in its words."""
    from pathlib import Path

    example = Path(__file__).resolve().parents[2] / "examples" / "range_bearing.py"
    summary = kalcal.verify(str(example), n=4000, seed=0).to_dict()
    result = answer(summary)
    assert result.tolerance == summary["effect_sizes"]["verdict"]
    assert "the tolerance verdict (band 0.1)" in result.sentence
    words = {"pass": "within the band", "fail": "outside it", "undecided": "undecided"}
    for test in summary["tests"]:
        outcome = test["tolerance_outcome"]
        clause = result.sentence.split("the tolerance verdict", 1)[1].split(". Exact tests:")[0]
        if outcome is not None:
            group = [part for part in clause.split("; ") if words[outcome] in part]
            assert any(test["name"] in part for part in group), (test["name"], outcome, result.sentence)
