"""Where the truth equals the filter, a failed check is a false alarm at its stated rate, never a cause.

A correct filter fails each check with probability at most 1 - confidence; a run whose truth equals its
filter that fails one has found one of those, and a direction ("the noise settings are too small/large")
or a model error would be a diagnosis of nothing. The seeds below are runs that fail ``nis`` at N = 100
(found by running seeds in order; the p-values are quoted so that a change of the draw shows here).
"""

import json
from pathlib import Path

import pytest

from kalcal.api.verification import compute_verification
from kalcal.scenarios.model_file.model import load_model_file
from kalcal.scenarios import build_scenario
from kalcal.stats.results import EXPLAINED_BY_TEXT, as_false_alarm

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
#: scale-bias whose filter is its truth's model: no sensor noise in the regressor, the filter's settings the truth's
SCALE_BIAS_EQUAL = ["truth.sensor_noise_std=0", "scenario.duration=10"]


def _failed(run):
    return [check for check in run.checks if not check.passed]


def _assert_false_alarms(failed):
    assert failed, "the seed no longer fails a check: choose another failing seed"
    for check in failed:
        assert check.cause.explained_by == "false_alarm" and check.cause.direction is None
        assert "False alarm: the truth equals the filter" in check.detail
        assert "rerun with another seed" in check.detail and "at most 0.01" in check.detail
        assert "noise settings" not in check.detail and "model" not in check.cause.reason
        assert check.detail.startswith(check.measured)


@pytest.mark.parametrize("seed", [14, 19])
def test_a_model_file_whose_truth_equals_its_filter_names_a_failure_a_false_alarm(seed):
    """examples/constant_velocity.toml (truth = filter) fails nis at these seeds (p = 0.0048, 0.0013): the
    cause said 'the noise settings are too large'."""
    run = compute_verification(load_model_file(EXAMPLES / "constant_velocity.toml"), 100, seed)
    assert run.summary["power_truth_equals_filter"] is True
    failed = _failed(run)
    assert "nis" in [check.name for check in failed]
    _assert_false_alarms(failed)
    written = {test["name"]: test for test in json.loads(json.dumps(run.summary, default=str))["tests"]}
    assert written["nis"]["cause"]["explained_by"] == "false_alarm"


def test_a_scale_bias_run_whose_truth_equals_its_filter_names_a_failure_a_false_alarm():
    scenario = build_scenario("scale-bias", None, SCALE_BIAS_EQUAL)
    assert scenario.truth_is_filter()
    _assert_false_alarms(_failed(compute_verification(scenario, 100, 242)))  # nis, p = 0.0067


@pytest.mark.parametrize(
    "settings",
    [
        [],  # sensor noise in the regressor: errors in variables
        ["truth.sensor_noise_std=0", "filter.reference_noise_std=0.3"],
        ["truth.sensor_noise_std=0", "filter.bias=0.2"],
        ["truth.sensor_noise_std=0", "scenario.drift=random-walk"],  # the filter's Q is 0 by default
        ["truth.sensor_noise_std=0", "scenario.excitation=reference"],
    ],
)
def test_a_scale_bias_filter_that_differs_from_its_truth_is_not_equal(settings):
    assert not build_scenario("scale-bias", None, settings).truth_is_filter()


def test_a_mistuned_filter_keeps_its_cause():
    """examples/constant_velocity_mistuned.toml: its failures keep their diagnosis."""
    run = compute_verification(load_model_file(EXAMPLES / "constant_velocity_mistuned.toml"), 2_000, 0)
    assert run.summary["power_truth_equals_filter"] is False
    failed = _failed(run)
    assert failed and all(check.cause.explained_by != "false_alarm" for check in failed)


def test_the_page_and_the_console_name_the_false_alarm(tmp_path):
    from typer.testing import CliRunner

    from kalcal.cli import app

    out = tmp_path / "run"
    args = ["verify", str(EXAMPLES / "constant_velocity.toml"), "-n", "100", "--seed", "14", "--out", str(out)]
    result = CliRunner().invoke(app, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output + result.stderr
    stdout = " ".join(result.stdout.split())  # the console wraps the paragraph of a failed check
    assert "nis: mean NIS" in stdout and "False alarm: the truth equals the filter" in stdout
    assert "noise settings are too" not in stdout
    page = (out / "report.html").read_text(encoding="utf-8")
    assert '<p class="cause">False alarm: the truth equals the filter' in page
    assert "Likely cause: False alarm" not in page and "noise settings too" not in page
    assert EXPLAINED_BY_TEXT["false_alarm"].split(":")[0] in page


def test_a_passed_check_is_left_as_it_is():
    run = compute_verification(load_model_file(EXAMPLES / "constant_velocity.toml"), 100, 0)
    for check in run.checks:
        assert check.passed and as_false_alarm(check) is check
