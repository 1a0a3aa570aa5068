"""The source report's figure numbers and its residual pair are quoted only for its setup: the settings
decide (:meth:`~kalcal.scenarios.protocol.Scenario.source_report`), not the scenario's class."""

import json

import pytest

from kalcal.api.verification import verify
from kalcal.scenarios import build_scenario


@pytest.mark.parametrize(
    "assignments, expected",
    [
        ([], True),
        (["scenario.gps_rate=10", "scenario.duration=6"], True),  # other values, the same study
        (["scenario.integration=trapezoid"], False),
        (["scenario.truth=discrete"], False),
        (["scenario.gps_fixes=velocity"], False),
        (["truth.scale_std=0.01", "filter.scale_std=0.01"], False),
        (["filter.scale_std=0.01"], False),
        (["truth.bias_walk_std=1e-5"], False),
        (["filter.bias_walk_std=1e-5"], False),
        (["truth.bias_correlation_time=50"], False),
    ],
)
def test_only_the_reports_setup_is_the_reports(assignments, expected):
    assert build_scenario("accel-gps", None, assignments).source_report() is expected


def test_other_scenarios_are_never_the_reports():
    assert build_scenario("scale-bias", None, []).source_report() is False
    assert build_scenario("scale-bias", None, []).residual_pair_times() is None


def test_the_residual_pair_is_the_reports_for_its_setup_alone():
    assert build_scenario("accel-gps", None, []).residual_pair_times() == (23.8, 5.8)
    assert build_scenario("accel-gps", None, ["scenario.integration=trapezoid"]).residual_pair_times() is None


@pytest.mark.parametrize("assignments, numbered", [([], True), (["scenario.integration=trapezoid"], False)])
def test_figures_carry_the_reports_numbers_only_for_its_setup(tmp_path, assignments, numbered):
    scenario = build_scenario("accel-gps", None, ["scenario.duration=4", *assignments])
    verify(scenario, 200, 5, tmp_path, long_run=0.0, report=True)
    page = (tmp_path / "report.html").read_text(encoding="utf-8")
    assert ("Figure 5.7." in page) is numbered
    assert ("Figure 5.3." in page) is numbered


def test_the_reports_residual_pair_only_for_its_setup(tmp_path):
    """A 30 s trapezoid run has updates at 23.8 s and 5.8 s, yet its E[r_k r_j^T] there is not the report's."""
    for name, assignments in (("euler", []), ("trapezoid", ["scenario.integration=trapezoid"])):
        verify(build_scenario("accel-gps", None, assignments), 100, 5, tmp_path / name, long_run=0.0, report=False)
    euler = json.loads((tmp_path / "euler" / "summary.json").read_text())
    trapezoid = json.loads((tmp_path / "trapezoid" / "summary.json").read_text())
    assert euler["residual_correlation"]["k_time"] == pytest.approx(23.8)
    assert trapezoid["residual_correlation"] is None
