"""Progress covers the whole job: both Monte Carlo runs, the statistics files and every figure."""

import json

import pytest

from kalcal.montecarlo.progress import STAGES, VERIFY_ORDER, stage
from kalcal.reporting.render import render_report
from kalcal.api.verification import verify
from kalcal.scenarios import build_scenario


def _record():
    calls = []
    return calls, lambda name, done, total: calls.append((name, done, total))


def _stages(calls):
    seen = []
    for name, _, _ in calls:
        if not seen or seen[-1] != name:
            seen.append(name)
    return seen


def test_verify_reports_every_stage_and_ends_each_complete(tmp_path):
    calls, progress = _record()
    scenario = build_scenario("accel-gps", None, ["scenario.duration=2"])
    outcome = verify(scenario, 5000, 1, tmp_path, long_run=4.0, progress=progress)
    assert _stages(calls) == ["monte carlo", "statistics", "long run", "statistics"]
    finals = {}
    for name, done, total in calls:
        assert 0 <= done <= total
        finals[name] = (done, total)
    assert finals["monte carlo"] == (5000, 5000) and finals["long run"] == (5000, 5000)
    assert [c for c in calls if c[0] == "statistics"] == [("statistics", 1, 3), ("statistics", 2, 3), ("statistics", 3, 3)]
    assert set(outcome.paths) == {"stats", "stats_long", "summary"}

    calls.clear()
    render_report(tmp_path, progress=progress)
    figures = [c for c in calls if c[0] == "figures"]
    drawn = len(list((tmp_path / "figures").glob("*.png")))
    assert [done for _, done, _ in figures] == list(range(1, drawn + 1))
    assert all(total == drawn for _, _, total in figures)
    assert calls[-1] == ("report", 1, 1)


def test_a_whole_verify_goes_through_the_stages_in_the_documented_order(tmp_path):
    calls, progress = _record()
    scenario = build_scenario("accel-gps", None, ["scenario.duration=2"])
    verify(scenario, 300, 1, tmp_path, long_run=4.0, progress=progress, report=True)
    assert tuple(_stages(calls)) == VERIFY_ORDER
    assert set(VERIFY_ORDER) == set(STAGES)


def test_without_a_long_run_the_statistics_count_two_files(tmp_path):
    calls, progress = _record()
    verify(build_scenario("accel-gps", None, ["scenario.duration=2"]), 300, 1, tmp_path, long_run=0, progress=progress)
    assert _stages(calls) == ["monte carlo", "statistics"]
    assert [c for c in calls if c[0] == "statistics"] == [("statistics", 1, 2), ("statistics", 2, 2)]


def test_stage_names_are_checked():
    assert stage(None, "monte carlo") is None
    with pytest.raises(ValueError, match="unknown progress stage 'figure'"):
        stage(lambda *a: None, "figure")
    assert list(STAGES) == ["monte carlo", "long run", "statistics", "figures", "report"]


def test_summary_json_carries_its_schema_version_and_its_nulls(tmp_path):
    verify(build_scenario("accel-gps", None, ["scenario.duration=2"]), 300, 1, tmp_path, long_run=0)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert list(summary)[0] == "schema_version" and summary["schema_version"] == 1
    # the report's pair is not in a 2 s run: a None, not a NaN, so nothing is counted
    assert summary["residual_correlation"] is None
    assert summary["nonfinite"]["count"] == sum(summary["nonfinite"]["fields"].values())


def test_an_infinite_statistic_is_written_as_null_and_counted_under_its_field(tmp_path, monkeypatch):
    import dataclasses
    import math

    import kalcal.api.verification as job

    real = job.run_checks

    def one_infinite(*args, **kwargs):
        checks = real(*args, **kwargs)
        return [dataclasses.replace(checks[0], statistic=math.inf), *checks[1:]]

    monkeypatch.setattr(job, "run_checks", one_infinite)
    verify(build_scenario("accel-gps", None, ["scenario.duration=2"]), 300, 1, tmp_path, long_run=0)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["tests"][0]["statistic"] is None
    assert all(test["statistic"] is not None for test in summary["tests"][1:])
    assert summary["nonfinite"] == {"count": 1, "fields": {"tests.statistic": 1}}
