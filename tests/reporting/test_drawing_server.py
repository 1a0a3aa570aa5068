"""The figure process of a job with a report: it draws the same page, its errors and interrupts are the job's,
and it leaves no process and no file behind."""

import multiprocessing
import os
import signal
import subprocess
import sys
import time

import pytest

import kalcal
from kalcal.errors import DataError
from kalcal.jobs.report import render_report
from kalcal.plots import ensemble
from kalcal.reporting import drawing, drawing_server

SMALL = {"scenario.duration": 2}

needs_server = pytest.mark.skipif(not drawing_server.wanted(), reason="no fork or one CPU: no figure process")


@pytest.fixture(autouse=True)
def _default_processes(monkeypatch):
    monkeypatch.delenv(drawing.PROCESSES_ENV, raising=False)


def _echo(value, *, progress=None):
    for done in range(1, 4):
        progress(done, 3)
    return value, os.getpid(), str(signal.getsignal(signal.SIGINT))


def _fail(*, progress=None):
    raise DataError("f1.png: cannot be drawn")


class _Unpicklable(Exception):
    """An error that holds what cannot be pickled (a function made on the spot)."""

    def __init__(self, why):
        super().__init__(why, lambda: None)

    def __str__(self):
        return self.args[0]


def _fail_oddly(*, progress=None):
    raise _Unpicklable("one and two")


_REAL_DRAW = drawing._draw
_LOG = None  #: where _slow_draw notes its writes


def _slow_draw(index, path):
    """A drawing worker's figure, half a second slower, noting who wrote it and when (the clock is the
    machine's, the same for every process)."""
    time.sleep(0.5)
    _REAL_DRAW(index, path)
    with open(_LOG, "a") as handle:
        handle.write(f"{os.getpid()} {time.monotonic()!r}\n")
    return path


def _running(pid: int) -> bool:
    """Whether process ``pid`` exists and is not a zombie."""
    try:
        with open(f"/proc/{pid}/stat") as handle:
            return handle.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


@needs_server
def test_a_call_runs_there_forwards_progress_and_ignores_an_interrupt():
    seen = []
    with drawing_server.serving(True) as server:
        assert drawing_server.current() is server
        os.kill(server.pid, signal.SIGINT)  # Ctrl-C reaches the whole process group
        time.sleep(0.2)
        assert server.process.is_alive()
        value, pid, handler = drawing_server.call(_echo, 7, progress=lambda done, total: seen.append((done, total)))
        assert drawing_server.current() is None  # it serves one call: the next is made here
        assert drawing_server.call(_echo, 8, progress=lambda done, total: None)[1] == os.getpid()
    assert (value, pid, handler) == (7, server.pid, str(signal.SIG_IGN))
    assert seen == [(1, 3), (2, 3), (3, 3)]
    assert multiprocessing.active_children() == [] and not _running(server.pid)


@needs_server
def test_its_errors_are_raised_here_with_their_type_and_message():
    with drawing_server.serving(True):
        with pytest.raises(DataError, match="^f1.png: cannot be drawn$"):
            drawing_server.call(_fail)
    with drawing_server.serving(True):
        with pytest.raises(RuntimeError, match="^_Unpicklable: one and two$"):
            drawing_server.call(_fail_oddly)
    assert multiprocessing.active_children() == []


def test_none_is_forked_without_a_report_with_one_process_asked_or_without_fork(monkeypatch):
    with drawing_server.serving(False) as server:
        assert server is None and drawing_server.current() is None
    monkeypatch.setenv(drawing.PROCESSES_ENV, "1")
    with drawing_server.serving(True) as server:
        assert server is None
    monkeypatch.delenv(drawing.PROCESSES_ENV)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0})  # one CPU
    assert not drawing_server.wanted()
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    monkeypatch.setattr(multiprocessing, "get_all_start_methods", lambda: ["spawn"])
    assert not drawing_server.wanted()
    assert drawing_server.call(_echo, 1, progress=lambda done, total: None)[1] == os.getpid()
    assert multiprocessing.active_children() == []


@needs_server
def test_it_exits_when_this_process_dies():
    code = (
        "import os\n"
        "from kalcal.reporting import drawing_server\n"
        "server = drawing_server.serving(True).__enter__()\n"
        "print(server.pid, flush=True)\n"
        "os._exit(0)\n"  # no clean-up: the figure process sees its pipe close
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    pid = int(done.stdout.strip())
    deadline = time.monotonic() + 60
    while _running(pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _running(pid)


def _verify(out, **kwargs):
    return kalcal.verify("accel-gps", 300, 1, SMALL, out=out, report=True, long_run=0, **kwargs)


@needs_server
def test_the_job_draws_there_the_bytes_of_a_redraw(tmp_path, monkeypatch):
    calls = []
    real = drawing_server.FigureProcess.call
    monkeypatch.setattr(drawing_server.FigureProcess, "call", lambda self, *a, **k: calls.append(1) or real(self, *a, **k))
    out = tmp_path / "out"
    _verify(out)
    assert calls == [1] and multiprocessing.active_children() == []
    copy = tmp_path / "copy"
    copy.mkdir()
    for name in ("summary.json", "stats.nc", ".kalcal-manifest.json"):
        (copy / name).write_bytes((out / name).read_bytes())
    render_report(copy)  # drawn here
    names = sorted(path.name for path in (out / "figures").glob("*.png"))
    assert len(names) >= 15 and names == sorted(path.name for path in (copy / "figures").glob("*.png"))
    for name in names:
        assert (out / "figures" / name).read_bytes() == (copy / "figures" / name).read_bytes(), name
    assert (out / "report.html").read_bytes() == (copy / "report.html").read_bytes()


@needs_server
def test_a_figures_error_there_is_the_one_line_of_drawing_here(tmp_path, monkeypatch):
    from typer.testing import CliRunner

    from kalcal.cli import app

    def broken(dataset, path, **kwargs):
        raise DataError(f"{path.name}: cannot be drawn")

    monkeypatch.setattr(ensemble, "plot_mean_error", broken)  # the figure process, forked after, inherits it
    lines = {}
    for processes in ("1", None):
        if processes is not None:
            monkeypatch.setenv(drawing.PROCESSES_ENV, processes)
        else:
            monkeypatch.delenv(drawing.PROCESSES_ENV)
        out = tmp_path / f"out{processes}"
        result = CliRunner().invoke(app, ["verify", "-n", "300", "--set", "scenario.duration=2", "--long-run", "0", "--out", str(out)])
        assert result.exit_code == 2
        lines[processes] = result.output.strip().splitlines()[-1:]
        assert not out.exists() and multiprocessing.active_children() == []
    assert lines["1"] == lines[None] and "mean_error.png: cannot be drawn" in lines[None][0]


@needs_server
def test_an_interrupt_during_the_report_stops_it_and_nothing_is_written_after(tmp_path, monkeypatch):
    log = tmp_path / "log"

    monkeypatch.setattr(sys.modules[__name__], "_LOG", log)
    monkeypatch.setattr(drawing, "_draw", _slow_draw)  # forked after this, the drawing workers run it
    totals = []

    def progress(stage, done, total):
        if stage == "figures":
            totals.append(total)
            raise KeyboardInterrupt

    out = tmp_path / "out"
    with pytest.raises(KeyboardInterrupt):
        _verify(out, progress=progress)
    raised = time.monotonic()
    assert multiprocessing.active_children() == []
    time.sleep(1.0)  # longer than a figure takes
    written = [line.split() for line in log.read_text().splitlines()]
    assert 1 <= len(written) < totals[0] // 2  # the figures not started were dropped
    assert all(float(when) < raised for _, when in written)  # nothing was written after the job gave up
    assert not any(_running(int(pid)) for pid, _ in written)  # its drawing workers are gone too
    assert not out.exists() and sorted(path.name for path in tmp_path.iterdir()) == ["log"]


@needs_server
def test_a_figure_process_that_died_leaves_the_drawing_to_the_job(tmp_path):
    killed = []

    def progress(stage, done, total):
        server = drawing_server.current()
        if stage == "statistics" and server is not None and not killed:
            os.kill(server.pid, signal.SIGKILL)
            server.process.join()
            killed.append(server.pid)

    out = tmp_path / "out"
    _verify(out, progress=progress)
    assert killed and multiprocessing.active_children() == []
    assert (out / "report.html").is_file() and len(list((out / "figures").glob("*.png"))) >= 15
