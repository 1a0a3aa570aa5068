"""A page's figures drawn in the job's figure process in two parts, the statistics' (drawn while the
realization shown is simulated) then the realization's: the figures, order, progress and bytes of drawing
them all at once, as a page drawn in the job's own process does."""

import re
import time
from pathlib import Path

import pytest

from kalcal.io import outputs
from kalcal.jobs import report as report_job
from kalcal.jobs.report import render_report
from kalcal.reporting import figure_names as names
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
    with fp.figure_process(names.REPORT_FIGURES, start=True):  # the job's: there the page is drawn in two parts
        render_report(run, realization=REALIZATION)
    assert [name for name, _, _ in seen] == [names.REPORT_STATISTICS_FIGURES, names.REPORT_REALIZATION_FIGURES]
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


def test_drawn_here_the_page_is_one_call_after_the_realization(copy_run, monkeypatch):
    """Without a figure process nothing would run meanwhile: the realization is redrawn first, then every
    figure drawn at once, the "figures" stage going 1, 2, ... up to every figure of the page."""
    run = copy_run()
    seen = _recorded(monkeypatch)
    events = []
    real = report_job.draw_realization
    monkeypatch.setattr(report_job, "draw_realization", lambda *a, **k: events.append("realization") or real(*a, **k))
    render_report(run, realization=REALIZATION, progress=lambda stage, done, total: events.append((stage, done, total)))
    assert [name for name, _, _ in seen] == [names.REPORT_FIGURES]
    assert events[0] == "realization"
    events = events[1:]
    counted = [(done, total) for stage, done, total in events if stage == "figures"]
    drawn = len(list((run / "figures").glob("*.png")))
    assert drawn >= 15
    assert counted == [(done, drawn) for done in range(1, drawn + 1)]


def test_in_the_figure_process_the_statistics_figures_are_drawn_while_the_realization_is_redrawn(
    report_run, copy_run, monkeypatch
):
    """With the job's figure process, the statistics' call is pending there while this process redraws the
    realization; the "figures" stage counts both calls as one, and the page and PNGs are the bytes drawn at
    once in this process (the saved run's)."""
    saved, page = report_run
    run = copy_run()
    busy = []
    real = report_job.draw_realization

    def spied(*args, **kwargs):
        busy.append(fp._CURRENT.get().busy)
        return real(*args, **kwargs)

    monkeypatch.setattr(report_job, "draw_realization", spied)
    events = []
    with fp.figure_process(names.REPORT_FIGURES, start=True) as process:
        assert fp.call("os:getpid") == process._process.pid  # loaded, and drawing there
        render_report(run, realization=REALIZATION, progress=lambda stage, done, total: events.append((stage, done, total)))
    assert busy == [True]
    drawn = sorted(p.name for p in (saved / "figures").glob("*.png"))
    assert [(d, t) for s, d, t in events if s == "figures"] == [(done, len(drawn)) for done in range(1, len(drawn) + 1)]
    assert sorted(p.name for p in (run / "figures").glob("*.png")) == drawn
    for name in drawn:
        assert (run / "figures" / name).read_bytes() == (saved / "figures" / name).read_bytes(), name
    assert (run / "report.html").read_bytes() == page.read_bytes()


class _Failed(Exception):
    pass


def test_a_failed_realization_stops_the_statistics_figures_and_leaves_the_folder(copy_run, monkeypatch):
    """The realization fails once the figure process has drawn a statistics figure into the staging folder
    (no progress asked for: the figure process hears of a stop in its progress all the same): the process
    is stopped before the error goes on, its running figures finish and the others are dropped (fewer than
    all of them are in the staging folder when it is removed), and the folder is as it was, then and a
    second later."""
    run = copy_run(figures=True)
    before = {p.relative_to(run): p.read_bytes() for p in run.rglob("*") if p.is_file()}
    statistics = len(list((run / "figures").glob("*.png"))) - REALIZATION_FIGURES_PER_STATE * 3
    staged = []
    real_rmtree = outputs.shutil.rmtree

    def counted_rmtree(path, *args, **kwargs):
        staged.append(len(list(Path(path).glob("figures/*.png"))))
        return real_rmtree(path, *args, **kwargs)

    monkeypatch.setattr(outputs.shutil, "rmtree", counted_rmtree)

    def fail(*args, **kwargs):
        deadline = time.monotonic() + 60
        while not list(run.glob(".kalcal-partial-*/figures/*.png")) and time.monotonic() < deadline:
            time.sleep(0.01)
        assert list(run.glob(".kalcal-partial-*/figures/*.png")), "no statistics figure was drawn"
        raise _Failed

    monkeypatch.setattr(report_job, "draw_realization", fail)
    with fp.figure_process(names.REPORT_FIGURES, start=True) as process:
        fp.call("os:getpid")  # loaded: the statistics' call is taken at once
        with pytest.raises(_Failed):
            render_report(run, realization=REALIZATION)
        assert process.ended and process._process.poll() is not None
        assert {p.relative_to(run): p.read_bytes() for p in run.rglob("*") if p.is_file()} == before
        assert len(staged) == 1 and 1 <= staged[0] < statistics, (staged, statistics)
        time.sleep(1.0)
    assert {p.relative_to(run): p.read_bytes() for p in run.rglob("*") if p.is_file()} == before
