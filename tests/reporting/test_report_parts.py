"""A page's figures in two parts: the statistics' (drawn while the realization shown is simulated), then
the realization's; together the figures, order and progress of drawing them all at once."""

import re

import pytest

from kalcal.jobs import report as report_job
from kalcal.jobs.report import render_report
from kalcal.reporting import figure_process as fp
from kalcal.reporting import figures
from kalcal.reporting.figure_entries import GROUPS, REALIZATION_FIGURES_PER_STATE, page_order

REALIZATION = 4321  # the saved run of tests/reporting/conftest.py


def _recorded(monkeypatch):
    """The two figure calls of the page (name, args, kwargs), recorded as they run here."""
    seen = []
    real_submit, real_call = fp.submit, fp.call

    def submit(name, *args, **kwargs):
        seen.append((name, args, kwargs))
        return real_submit(name, *args, **kwargs)

    def call(name, *args, **kwargs):
        seen.append((name, args, kwargs))
        return real_call(name, *args, **kwargs)

    monkeypatch.setattr(report_job, "submit", submit)
    monkeypatch.setattr(report_job, "call", call)
    return seen


def test_the_two_parts_are_the_page_drawn_at_once(copy_run, monkeypatch, tmp_path):
    """The statistics' figures, then the realization's (two per state), joined in page order: the entries,
    skipped figures and PNG bytes of render_figures drawing them all from the same inputs."""
    run = copy_run()
    seen = _recorded(monkeypatch)
    render_report(run, realization=REALIZATION)
    assert [name for name, _, _ in seen] == [fp.REPORT_STATISTICS_FIGURES, fp.REPORT_REALIZATION_FIGURES]
    (_, (dataset, _, long_dataset), options), (_, (data, _), _) = seen
    options = {key: value for key, value in options.items() if key != "progress"}

    statistics, skipped = figures.render_statistics_figures(dataset, tmp_path / "parts", long_dataset, **options)
    shown = figures.render_realization_figures(data, tmp_path / "parts", scenario=options["scenario"])
    assert len(shown) == REALIZATION_FIGURES_PER_STATE * len(data.state_names) == 6
    whole, whole_skipped = figures.render_figures(dataset, data, tmp_path / "whole", long_dataset, **options)
    joined = page_order(shown + statistics)

    def described(entries):
        return [(e.key, e.group, e.title, e.caption, e.path.name, e.number) for e in entries]

    assert described(joined) == described(whole)
    assert skipped == whole_skipped
    assert [e.key for e in joined][:4] == ["state_bias", "state_velocity", "state_position", "error_position"]
    for entry in whole:
        assert (tmp_path / "parts" / entry.path.name).read_bytes() == entry.path.read_bytes(), entry.key
        assert (run / "figures" / entry.path.name).read_bytes() == entry.path.read_bytes(), entry.key
    # the page shows them group by group, each in render_figures' order
    page = (run / "report.html").read_text(encoding="utf-8")
    shown_order = list(dict.fromkeys(re.findall(r'figures/([a-z_]+\.png)', page)))
    assert shown_order == [e.path.name for group, _ in GROUPS for e in whole if e.group == group]


def test_the_figures_progress_counts_both_parts_as_one(copy_run):
    """The "figures" stage goes 1, 2, ... up to every figure of the page, against one total."""
    run = copy_run()
    events = []
    render_report(run, realization=REALIZATION, progress=lambda stage, done, total: events.append((stage, done, total)))
    counted = [(done, total) for stage, done, total in events if stage == "figures"]
    drawn = len(list((run / "figures").glob("*.png")))
    assert drawn >= 15
    assert counted == [(done, drawn) for done in range(1, drawn + 1)]


class _Failed(Exception):
    pass


def test_a_failed_realization_stops_the_statistics_figures_and_leaves_the_folder(copy_run, monkeypatch):
    """The realization fails while the figure process draws the statistics' figures: it is stopped before
    the error goes on (its running figures finish, the others are dropped), and the folder is as it was."""
    run = copy_run(figures=True)
    before = {p.relative_to(run): p.read_bytes() for p in run.rglob("*") if p.is_file()}

    def fail(*args, **kwargs):
        raise _Failed

    monkeypatch.setattr(report_job, "draw_realization", fail)
    with fp.figure_process(fp.REPORT_FIGURES, start=True) as process:
        with pytest.raises(_Failed):
            render_report(run, realization=REALIZATION)
        assert process.ended and process._process.poll() is not None
    assert {p.relative_to(run): p.read_bytes() for p in run.rglob("*") if p.is_file()} == before
