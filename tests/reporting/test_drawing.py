"""The report's figures drawn in parallel processes are the same files as drawn one by one."""

import multiprocessing
import os
import re
import signal
import threading
import time

import pytest

from kalcal.errors import ConfigError, DataError
from kalcal.jobs.report import render_report
from kalcal.reporting import drawing


def test_parallel_figures_are_the_serial_bytes(report_run, copy_run, monkeypatch):
    """report_run drew its figures with the default workers; a copy drawn in this process matches."""
    saved, _ = report_run
    serial = copy_run()
    monkeypatch.setattr(drawing, "drawing_workers", lambda figures: 1)
    render_report(serial, realization=4321)
    names = sorted(p.name for p in (saved / "figures").glob("*.png"))
    assert len(names) >= 15
    assert names == sorted(p.name for p in (serial / "figures").glob("*.png"))
    for name in names:
        assert (saved / "figures" / name).read_bytes() == (serial / "figures" / name).read_bytes(), name


def _write(path):
    path.write_text(path.stem)
    return path


def _fail(path):
    raise DataError(f"{path.name}: cannot be drawn")


@pytest.mark.skipif("fork" not in multiprocessing.get_all_start_methods(), reason="no fork on this platform")
def test_results_in_order_progress_counted_and_errors_raised(tmp_path):
    paths = [tmp_path / f"f{i}.png" for i in range(5)]
    seen = []
    written = drawing.draw_all([_write] * 5, paths, workers=2, progress=lambda done, total: seen.append((done, total)))
    assert written == paths
    assert [p.read_text() for p in paths] == [f"f{i}" for i in range(5)]
    assert seen == [(i, 5) for i in range(1, 6)]
    with pytest.raises(DataError, match="f1.png: cannot be drawn"):
        drawing.draw_all([_write, _fail, _write], paths[:3], workers=2)


def test_one_worker_per_cpu_at_most_one_per_figure():
    assert drawing.drawing_workers(1) == 1
    assert 1 <= drawing.drawing_workers(100) <= multiprocessing.cpu_count()


def _slow(path):
    time.sleep(0.1)
    return _write(path)


needs_fork = pytest.mark.skipif("fork" not in multiprocessing.get_all_start_methods(), reason="no fork on this platform")


def _signal_handler(path):
    path.write_text(str(signal.getsignal(signal.SIGINT)))
    return path


@needs_fork
def test_workers_leave_an_interrupt_to_this_process(tmp_path):
    paths = [tmp_path / f"f{i}.png" for i in range(2)]
    drawing.draw_all([_signal_handler] * 2, paths, workers=2)
    assert [p.read_text() for p in paths] == [str(signal.SIG_IGN)] * 2
    assert signal.getsignal(signal.SIGINT) is not signal.SIG_IGN  # this process still hears it


def _freeze_count(path):
    import gc

    path.write_text(str(gc.get_freeze_count()))
    return path


@needs_fork
def test_a_worker_leaves_what_it_inherited_to_the_collector_s_permanent_generation(tmp_path):
    """A worker freezes the heap it forked with (matplotlib, the figures' data): its collections traverse
    only its figures' own objects. This process's collector is left as it was."""
    import gc

    before = gc.get_freeze_count()
    paths = [tmp_path / f"f{i}.png" for i in range(2)]
    drawing.draw_all([_freeze_count] * 2, paths, workers=2)
    assert all(int(p.read_text()) > before + 1000 for p in paths)
    assert gc.get_freeze_count() == before


@needs_fork
def test_an_error_drops_the_figures_not_started_and_leaves_no_process(tmp_path):
    paths = [tmp_path / f"f{i}.png" for i in range(20)]
    with pytest.raises(DataError, match="^f0.png: cannot be drawn$"):
        drawing.draw_all([_fail] + [_slow] * 19, paths, workers=2)
    assert multiprocessing.active_children() == []
    assert len(list(tmp_path.glob("*.png"))) < 10  # not every figure was drawn after the error


def _fail_late(path):
    time.sleep(0.5)
    raise DataError(f"{path.name}: cannot be drawn")


@needs_fork
def test_the_error_raised_is_the_first_failing_figure_s_in_page_order_as_drawn_one_by_one(tmp_path):
    """The second figure fails at once, the first half a second later: the first one's error, whichever
    the workers met first."""
    paths = [tmp_path / f"f{i}.png" for i in range(2)]
    with pytest.raises(DataError, match="^f0.png: cannot be drawn$"):
        drawing.draw_all([_fail_late, _fail], paths, workers=2)
    with pytest.raises(DataError, match="^f0.png: cannot be drawn$"):
        drawing.draw_all([_fail_late, _fail], paths, workers=1)


def test_fallback_to_this_process(monkeypatch):
    monkeypatch.delenv(drawing.PROCESSES_ENV, raising=False)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1, 2, 3})
    assert drawing.drawing_workers(18) == (4 if "fork" in multiprocessing.get_all_start_methods() else 1)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0})  # one CPU
    assert drawing.drawing_workers(18) == 1
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1, 2, 3})
    monkeypatch.setenv(drawing.PROCESSES_ENV, "1")  # asked for
    assert drawing.drawing_workers(18) == 1
    monkeypatch.setenv(drawing.PROCESSES_ENV, "2")
    assert drawing.drawing_workers(18) == (2 if "fork" in multiprocessing.get_all_start_methods() else 1)
    monkeypatch.delenv(drawing.PROCESSES_ENV)
    monkeypatch.setattr(multiprocessing, "get_all_start_methods", lambda: ["spawn"])  # no fork (not Linux)
    assert drawing.drawing_workers(18) == 1


# "²" passes str.isdigit() but not int(); "٣" (Arabic-Indic three) and "１" (fullwidth one) pass int():
# only ASCII digits are a count; "+2" and "1_0" pass int() too
@pytest.mark.parametrize("value", ["0", "two", "-1", "²", "٣", "１", "+2", "1_0", "2.0"])
def test_a_bad_process_count_is_refused_in_one_line(monkeypatch, value):
    monkeypatch.setenv(drawing.PROCESSES_ENV, value)
    with pytest.raises(ConfigError, match=f"^{drawing.PROCESSES_ENV}: expected a whole number >= 1, got {re.escape(repr(value))}$"):
        drawing.drawing_workers(18)


@pytest.mark.parametrize("value", ["²", "٣"])
def test_a_bad_process_count_is_one_line_and_exit_2_on_the_command_line(copy_run, monkeypatch, value):
    from typer.testing import CliRunner

    from kalcal.cli import app

    run = copy_run()
    monkeypatch.setenv(drawing.PROCESSES_ENV, value)
    result = CliRunner().invoke(app, ["report", str(run)])
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and drawing.PROCESSES_ENV in lines[0] and "Traceback" not in result.output
    assert not (run / "report.html").exists() and not (run / "figures").exists()


def test_serial_drawing_calls_every_figure_in_order(tmp_path, monkeypatch):
    monkeypatch.setenv(drawing.PROCESSES_ENV, "1")
    paths = [tmp_path / f"f{i}.png" for i in range(3)]
    seen = []
    assert drawing.draw_all([_write] * 3, paths, progress=lambda d, t: seen.append(d)) == paths
    assert seen == [1, 2, 3] and multiprocessing.active_children() == []


def test_a_bad_process_count_stops_a_verify_before_its_monte_carlo(tmp_path, monkeypatch):
    from kalcal.jobs import verify as verify_job
    from kalcal.models.registry import build_scenario

    ran = []
    monkeypatch.setattr(verify_job, "run_monte_carlo", lambda *args, **kwargs: ran.append(1))
    monkeypatch.setenv(drawing.PROCESSES_ENV, "0")
    with pytest.raises(ConfigError, match=f"^{drawing.PROCESSES_ENV}: expected a whole number >= 1, got '0'$"):
        verify_job.verify(build_scenario("accel-gps", None, ["scenario.duration=2"]), 300, 1, tmp_path / "out", report=True)
    assert ran == [] and not (tmp_path / "out").exists()


def test_a_figures_error_in_a_worker_is_the_one_line_of_serial_drawing(copy_run, monkeypatch):
    from typer.testing import CliRunner

    from kalcal.cli import app
    from kalcal.plots import ensemble

    def broken(dataset, path, **kwargs):
        raise DataError(f"{path.name}: cannot be drawn")

    monkeypatch.setattr(ensemble, "plot_mean_error", broken)  # the forked workers inherit it
    lines = {}
    run = copy_run()
    for processes in ("1", "2"):
        monkeypatch.setenv(drawing.PROCESSES_ENV, processes)
        result = CliRunner().invoke(app, ["report", str(run)])
        assert result.exit_code == 2
        lines[processes] = result.output.strip().splitlines()
        assert not (run / "report.html").exists() and not (run / "figures").exists()  # the folder as it was
        assert multiprocessing.active_children() == []
    assert lines["1"] == lines["2"] and len(lines["1"]) == 1 and "mean_error.png: cannot be drawn" in lines["1"][0]


SHORT_RUN = ("-n", "100", "--long-run", "0", "--set", "scenario.duration=2")


def test_a_bad_process_count_stops_a_cli_verify_with_its_report_before_the_monte_carlo(tmp_path, monkeypatch):
    from typer.testing import CliRunner

    from kalcal.cli import app
    from kalcal.jobs import verify as verify_job

    ran = []
    monkeypatch.setattr(verify_job, "run_monte_carlo", lambda *args, **kwargs: ran.append(1))
    monkeypatch.setenv(drawing.PROCESSES_ENV, "0")
    result = CliRunner().invoke(app, ["verify", *SHORT_RUN, "--out", str(tmp_path / "out")])
    assert result.exit_code == 2
    assert result.output.strip().splitlines() == [f"kalcal: error: {drawing.PROCESSES_ENV}: expected a whole number >= 1, got '0'"]
    assert ran == [] and not (tmp_path / "out").exists()


def test_a_bad_process_count_stops_an_api_verify_with_a_report_before_the_monte_carlo(tmp_path, monkeypatch):
    import kalcal
    from kalcal.jobs import verify as verify_job

    ran = []
    monkeypatch.setattr(verify_job, "run_monte_carlo", lambda *args, **kwargs: ran.append(1))
    monkeypatch.setenv(drawing.PROCESSES_ENV, "²")
    with pytest.raises(ConfigError, match=f"^{drawing.PROCESSES_ENV}: expected a whole number >= 1, got '²'$"):
        kalcal.verify("accel-gps", 100, settings={"scenario.duration": 2}, long_run=0, out=tmp_path / "out", report=True)
    assert ran == [] and not (tmp_path / "out").exists()


def test_a_bad_process_count_does_not_refuse_a_run_that_draws_no_figures(tmp_path, monkeypatch):
    """verify --no-report, a sweep (its runs have no page), a verify in memory: none of them forks a drawing
    process, so none of them reads KALCAL_FIGURE_PROCESSES."""
    from typer.testing import CliRunner

    import kalcal
    from kalcal.cli import app

    monkeypatch.setenv(drawing.PROCESSES_ENV, "0")
    runner = CliRunner()
    result = runner.invoke(app, ["verify", *SHORT_RUN, "--no-report", "--out", str(tmp_path / "verify")])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "verify" / "summary.json").is_file() and not (tmp_path / "verify" / "report.html").exists()
    sweep = ["sweep", "-n", "100", "--set", "scenario.duration=2,3", "--out", str(tmp_path / "sweep")]
    result = runner.invoke(app, sweep)
    assert result.exit_code == 0, result.output
    assert (tmp_path / "sweep" / "sweep.csv").is_file()
    result = kalcal.verify("accel-gps", 100, settings={"scenario.duration": 2}, long_run=0)
    assert result.run.summary["realizations"] == 100
    result = kalcal.verify("accel-gps", 100, settings={"scenario.duration": 2}, long_run=0, out=tmp_path / "api", report=False)
    assert (tmp_path / "api" / "summary.json").is_file()


def test_a_bad_process_count_stops_a_redraw_before_it_reads_the_run(copy_run, monkeypatch):
    from kalcal.jobs import report as report_job

    read = []
    monkeypatch.setattr(report_job, "load_statistics", lambda path: read.append(path))
    monkeypatch.setattr(report_job, "read_summary", lambda path: read.append(path))
    monkeypatch.setenv(drawing.PROCESSES_ENV, "0")
    with pytest.raises(ConfigError, match=f"^{drawing.PROCESSES_ENV}: expected a whole number >= 1, got '0'$"):
        render_report(copy_run())
    assert read == []


def _child_pids():
    """This process's children, as the kernel counts them (zombies included: a child not joined)."""
    me = os.getpid()
    pids = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as handle:
                    fields = handle.read().rpartition(")")[2].split()
            except OSError:
                continue  # it ended while being read
            if int(fields[1]) == me:
                pids.append(int(entry))
    return pids


def _folder(path):
    return {p.relative_to(path).as_posix(): p.read_bytes() for p in sorted(path.rglob("*")) if p.is_file()}


@needs_fork
@pytest.mark.skipif(not os.path.isdir("/proc"), reason="children counted from /proc")
def test_an_interrupt_while_workers_draw_leaves_the_folder_and_no_process(tmp_path, monkeypatch):
    from kalcal.interrupts import Interrupted
    from kalcal.jobs import verify as verify_job
    from kalcal.models.registry import build_scenario

    scenario = build_scenario("accel-gps", None, ["scenario.duration=2"])
    out = tmp_path / "out"
    monkeypatch.setenv(drawing.PROCESSES_ENV, "2")
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})  # two workers on a one-CPU machine too
    others = set(_child_pids())  # this process's children from before (another test's, under xdist)
    verify_job.verify(scenario, 300, 1, out, long_run=0, report=True)  # the previous run, with its page
    before = _folder(out)
    assert "report.html" in before and any(name.startswith("figures/") for name in before)
    workers = []

    def progress(stage, done, total):
        if stage == "figures" and done == 2:  # two figures written, others being drawn
            workers.append(len(multiprocessing.active_children()))
            raise Interrupted(signal.SIGINT)

    with pytest.raises(Interrupted):
        verify_job.verify(scenario, 300, 2, out, long_run=0, report=True, progress=progress)
    assert workers == [2]  # interrupted while two drawing processes were alive
    assert multiprocessing.active_children() == [] and set(_child_pids()) <= others
    assert _folder(out) == before  # the previous run's files, byte for byte, and nothing else
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no staged set left beside it


def _threads(path):
    path.write_text(str(len(threading.enumerate())))
    return path


@needs_fork
def test_a_worker_holds_only_the_thread_that_forked_it(tmp_path):
    """Another thread alive in this process at the fork (the progress bar's, a Dask client's) is not in
    the drawing workers."""
    stop = threading.Event()
    other = threading.Thread(target=stop.wait, name="another thread")
    other.start()
    try:
        paths = [tmp_path / f"f{i}.png" for i in range(2)]
        drawing.draw_all([_threads] * 2, paths, workers=2)
    finally:
        stop.set()
        other.join()
    assert [p.read_text() for p in paths] == ["1", "1"]


def test_the_engines_threads_have_ended_when_the_figures_are_drawn(tmp_path):
    from kalcal.jobs import verify as verify_job
    from kalcal.models.registry import build_scenario

    alive = []

    def progress(stage, done, total):
        if stage == "figures" and done == 1:
            alive.extend(t.name for t in threading.enumerate() if t.name.startswith("ThreadPoolExecutor"))
            alive.append("checked")

    scenario = build_scenario("accel-gps", None, ["scenario.duration=2"])
    verify_job.verify(scenario, 300, 1, tmp_path / "out", long_run=0, report=True, workers=2, progress=progress)
    assert alive == ["checked"]
