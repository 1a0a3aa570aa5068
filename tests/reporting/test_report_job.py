"""``render_report``: from a saved run to figures and page, reproducibly, and its errors on bad input."""

import json

import numpy as np
import pytest

from kalcal.errors import ConfigError, DataError
from kalcal.io.statistics import read_statistics
from kalcal.reporting.render import draw_realization, render_report, settings_assignments
from kalcal.scenarios import build_scenario
from kalcal.montecarlo.engine import block_sizes, run_block
from kalcal.montecarlo.scenarios import build_problem

N, SEED, REALIZATION = 5000, 3, 4321  # the saved run of tests/reporting/conftest.py


def test_render_twice_gives_identical_page_and_figures(report_run, copy_run):
    """Rendering again from the files (here in a copy of the run directory, over the first rendering) gives
    the same bytes as the job's page, drawn from the run in memory."""
    out, page = report_run
    run = copy_run(figures=True)
    figures = {p.name: p.read_bytes() for p in (out / "figures").glob("*.png")}
    again = render_report(run, realization=REALIZATION)
    assert again == run / "report.html"
    assert again.read_bytes() == page.read_bytes()
    assert {p.name: p.read_bytes() for p in (run / "figures").glob("*.png")} == figures


def test_without_long_run_the_figure_is_skipped_with_a_note(copy_run):
    run = copy_run(exclude=("stats_long.nc",))
    (run / "figures").mkdir()
    (run / "figures" / "mean_error_long.png").write_bytes(b"stale")
    page = render_report(run).read_text(encoding="utf-8")
    assert "Figure 5.8 (Ensemble mean error over a longer run) is not shown:" in page
    assert not (run / "figures" / "mean_error_long.png").exists()
    assert "Figure 5.7." in page and "Realization 0 of the 5,000" in page


def test_realization_is_the_ensembles(report_run):
    """The blocks redrawn for the report are the ensemble's: their mean error is the saved one."""
    out, _ = report_run
    summary = json.loads((out / "summary.json").read_text())
    problem, _ = build_problem(build_scenario(summary["scenario"], None, settings_assignments(summary["settings"])))
    blocks = [run_block(problem, SEED, b, size, "exact") for b, size in enumerate(block_sizes(N))]
    errors = np.concatenate([b.error for b in blocks])
    estimates = np.concatenate([b.estimate for b in blocks])
    assert errors.shape[0] == N
    saved = read_statistics(out / "stats.nc")
    np.testing.assert_allclose(errors.mean(axis=0), saved["mean_error"].values, rtol=0, atol=1e-12)
    # the last realization sits in the short last block
    one = draw_realization(problem, SEED, N - 1, N, "exact")
    scale = np.abs(estimates[-1]).max(axis=0) + np.abs(errors[-1]).max(axis=0)  # each state's size
    for shown, ensemble in ((one.error, errors[-1]), (one.estimate, estimates[-1])):  # the compiled block: rounding
        assert np.all(np.abs(shown - ensemble) <= 1e-12 * scale)
    np.testing.assert_allclose(one.filter_cov, saved["filter_cov"].values, rtol=1e-12, atol=0)


def test_settings_assignments_skip_unset_values():
    settings = {"scenario": {"duration": 6.0, "truth": "analytic"}, "filter": {"bias_std": None, "accel_noise_std": 0.03}}
    assert settings_assignments(settings) == ["scenario.duration=6.0", "scenario.truth=analytic", "filter.accel_noise_std=0.03"]


def test_missing_directory(tmp_path):
    with pytest.raises(DataError, match="no such run directory"):
        render_report(tmp_path / "nowhere")


def test_missing_summary(copy_run):
    run = copy_run(exclude=("summary.json",))
    with pytest.raises(DataError, match="summary.json: no such file"):
        render_report(run)


def test_missing_statistics(copy_run):
    run = copy_run(exclude=("stats.nc",))
    with pytest.raises(DataError, match="stats.nc: no such statistics file"):
        render_report(run)


def test_broken_summary(copy_run):
    run = copy_run()
    (run / "summary.json").write_text("{not json")
    with pytest.raises(DataError, match="not valid JSON"):
        render_report(run)
    (run / "summary.json").write_text(json.dumps({"scenario": "accel-gps"}))
    with pytest.raises(DataError, match="missing settings"):
        render_report(run)


@pytest.mark.parametrize("index", [N, N + 10, -1])
def test_realization_out_of_range(report_run, index):
    with pytest.raises(ConfigError, match=r"--realization: expected 0 <= K < 5,000"):
        render_report(report_run[0], realization=index)


def test_settings_that_do_not_match_the_statistics(copy_run):
    run = copy_run()
    summary = json.loads((run / "summary.json").read_text())
    summary["settings"]["scenario"]["duration"] = 8.0
    (run / "summary.json").write_text(json.dumps(summary))
    with pytest.raises(DataError, match="update times do not match"):
        render_report(run)
    summary["settings"]["scenario"]["duration"] = -1
    (run / "summary.json").write_text(json.dumps(summary))
    with pytest.raises(ConfigError, match="scenario.duration"):
        render_report(run)


def test_a_summary_of_a_newer_layout_is_refused_in_one_line(copy_run):
    from typer.testing import CliRunner

    from kalcal.cli import app
    from kalcal.io.results import SCHEMA_VERSION

    run = copy_run()
    summary = json.loads((run / "summary.json").read_text())
    summary["schema_version"] = SCHEMA_VERSION + 1
    (run / "summary.json").write_text(json.dumps(summary))
    result = CliRunner().invoke(app, ["report", str(run)])
    assert result.exit_code == 2
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and f"schema_version {SCHEMA_VERSION + 1} is newer than this kalcal reads" in lines[0]
    assert not (run / "report.html").exists()
    summary["schema_version"] = "1"
    (run / "summary.json").write_text(json.dumps(summary))
    with pytest.raises(DataError, match="schema_version must be a whole number"):
        render_report(run)


def test_a_summary_from_before_schema_version_still_renders(copy_run):
    run = copy_run()
    summary = json.loads((run / "summary.json").read_text())
    del summary["schema_version"], summary["nonfinite"]
    (run / "summary.json").write_text(json.dumps(summary))
    page = render_report(run).read_text(encoding="utf-8")
    assert "Figure 5.7." in page


def test_the_page_is_drawn_from_the_folders_summary_alone():
    """A redraw reads DIR/summary.json: no caller hands it a summary of its own (the verify job draws its
    page with draw_report)."""
    import inspect

    assert list(inspect.signature(render_report).parameters) == ["out", "realization", "progress"]


class _Stop(Exception):
    pass


@pytest.mark.parametrize("job", ["render_report", "draw_report"])
def test_the_run_numbers_are_checked_once_per_page(copy_run, monkeypatch, job):
    """N, the seed and the shown realization are read from the summary and checked once, before the
    statistics, and handed to the drawing (stopped here before its figures)."""
    from kalcal.reporting import render as report_job

    calls = []
    real = report_job._run_numbers
    monkeypatch.setattr(report_job, "_run_numbers", lambda *args: calls.append(args[2]) or real(*args))

    def stop(*args, **kwargs):
        raise _Stop

    monkeypatch.setattr("kalcal.reporting.figures.render_figures", stop)  # the function the page's call runs
    run = copy_run()
    with pytest.raises(_Stop):
        if job == "render_report":
            render_report(run, realization=REALIZATION)
        else:
            summary = json.loads((run / "summary.json").read_text(encoding="utf-8"))
            report_job.draw_report(run, summary, read_statistics(run / "stats.nc"), realization=REALIZATION)
    assert calls == [REALIZATION]
