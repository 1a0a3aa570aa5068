"""summary.json's timing: total_s up to the summary, report_s for the page, wall_s for the whole job, long_run_s
for the long-run study's own Monte Carlo."""

import json
import time

from kalcal.reporting import render as report_job
from kalcal.api import verification as save_job
from kalcal.api.verification import verify
from kalcal.scenarios import build_scenario

PAUSE = 0.5  # s added to drawing the report


def test_wall_time_covers_the_whole_job_report_included(tmp_path, monkeypatch):
    real = report_job.draw_report  # what the job draws its page with

    def slow_report(*args, **kwargs):
        time.sleep(PAUSE)
        return real(*args, **kwargs)

    monkeypatch.setattr(report_job, "draw_report", slow_report)
    out = tmp_path / "out"
    started = time.perf_counter()
    outcome = verify(build_scenario("accel-gps", None, ["scenario.duration=2"]), 300, 1, out, long_run=4.0, report=True)
    elapsed = time.perf_counter() - started
    timing = json.loads((out / "summary.json").read_text())["timing"]
    assert timing == json.loads(json.dumps(outcome.summary["timing"]))
    assert timing["report_s"] >= PAUSE
    assert timing["wall_s"] >= timing["total_s"] + timing["report_s"]
    assert timing["wall_s"] <= elapsed
    # the long run's own Monte Carlo: inside total_s, apart from the run's, as long_run says
    assert 0 < timing["long_run_s"] == outcome.summary["long_run"]["monte_carlo_s"]
    assert timing["monte_carlo_s"] + timing["long_run_s"] < timing["total_s"]
    page = (out / "report.html").read_text(encoding="utf-8")
    assert "timing.wall_s" in page and "timing.report_s" in page
    assert ">wall_s<" not in page and ">report_s<" not in page
    # a redraw reads the rewritten summary and still gives the same page
    before = (out / "report.html").read_bytes()
    report_job.render_report(out)
    assert (out / "report.html").read_bytes() == before


def test_without_a_report_its_time_is_null(tmp_path):
    verify(build_scenario("accel-gps", None, ["scenario.duration=2"]), 300, 1, tmp_path, long_run=0)
    timing = json.loads((tmp_path / "summary.json").read_text())["timing"]
    assert timing["report_s"] is None
    assert timing["wall_s"] >= timing["total_s"] > 0
    assert timing["long_run_s"] == 0.0  # no long run


def test_the_summary_is_written_once_after_the_page(tmp_path, monkeypatch):
    written = []
    real = save_job.write_json

    def counting(path, document):
        written.append((path.name, (path.parent / "report.html").is_file()))
        return real(path, document)

    monkeypatch.setattr(save_job, "write_json", counting)
    verify(build_scenario("accel-gps", None, ["scenario.duration=2"]), 300, 1, tmp_path / "out", long_run=0, report=True)
    assert written == [("summary.json", True)]
