"""The figure process (:mod:`kalcal.reporting.figure_process`): calls run there and answer here, errors
and progress come back, an interrupt stops it before the error goes on, a dead one is drawn around, it
dies with the job, and the commands that draw never load matplotlib themselves."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from kalcal.errors import DataError
from kalcal.reporting import figure_names as names
from kalcal.reporting import figure_process as fp

CALLS = "tests.reporting.figure_calls"
#: the commands start a figure process only with two usable CPUs or more (one CPU has nothing to overlap)
two_cpus = pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2 if hasattr(os, "sched_getaffinity") else False,
                              reason="a figure process starts with two usable CPUs or more")  # fmt: skip
linux_only = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with open(f"/proc/{pid}/stat") as handle:  # a zombie (not reaped yet) has ended
        return handle.read().split(")")[1].split()[0] != "Z"


def test_a_call_runs_in_the_figure_process_and_passes_its_progress_back():
    seen = []
    with fp.figure_process(f"{CALLS}:pid_and_progress", start=True) as process:
        assert process is not None
        pid = fp.call(f"{CALLS}:pid_and_progress", 3, progress=lambda done, total: seen.append((done, total)))
        assert pid != os.getpid()  # drawn there
        assert fp.call("os:getpid") == pid  # one process, one call at a time
    assert seen == [(1, 3), (2, 3), (3, 3)]
    assert process.ended and not _alive(pid)  # the block's end ends it


def test_without_a_figure_process_a_call_runs_here():
    with fp.figure_process(f"{CALLS}:pid_and_progress", start=False) as process:
        assert process is None
        assert fp.call(f"{CALLS}:pid_and_progress", 2) == os.getpid()
    assert fp.call("os:getpid") == os.getpid()  # outside any block too


def test_an_error_there_is_raised_here_as_itself():
    with fp.figure_process(f"{CALLS}:refuse", start=True):
        with pytest.raises(DataError, match="^x.png: cannot be drawn$"):
            fp.call(f"{CALLS}:refuse", "x.png")
        assert fp.call("os:getpid") != os.getpid()  # still there for the next call


def test_a_pending_figure_as_a_with_block_waits_raises_its_error_or_stops_behind_the_blocks(tmp_path):
    """``with submit(...)``: the figure's value once the block ends; its error raised at the block's end;
    a failing block's own error goes on (not the figure's), the figure process stopped before it does."""
    with fp.figure_process(f"{CALLS}:pid_of", start=True) as process:
        with fp.submit(f"{CALLS}:pid_of", None) as figure:
            pass
        assert figure.result() == process._process.pid
        with pytest.raises(DataError, match="^x.png: cannot be drawn$"), fp.submit(f"{CALLS}:refuse", "x.png"):
            pass
    with fp.figure_process(f"{CALLS}:slow_files", start=True) as process:
        fp.call("os:getpid")  # loaded: the figure is taken at once
        with pytest.raises(KeyError, match="the block's own"):
            with fp.submit(f"{CALLS}:slow_files", str(tmp_path), 2):
                raise KeyError("the block's own")
        assert process.ended and process._process.poll() is not None


def test_a_dead_figure_process_is_drawn_around_here():
    with fp.figure_process("os:getpid", start=True) as process:
        process._process.kill()
        process._process.wait()
        assert fp.call("os:getpid") == os.getpid()
        assert process.ended
        assert fp.call("os:getpid") == os.getpid()  # and so are the later calls


def test_modules_that_do_not_load_there_leave_the_calls_to_this_process():
    with fp.figure_process("kalcal_no_such_module:draw", start=True):
        assert fp.call("os:getpid") == os.getpid()


def test_a_pending_call_gives_its_result_once_and_cancel_stops_the_process(tmp_path):
    with fp.figure_process(f"{CALLS}:slow_files", start=True) as process:
        pending = fp.submit(f"{CALLS}:slow_files", str(tmp_path), 2)
        assert [p.name for p in pending.result()] == ["f0.txt", "f1.txt"]
        assert pending.result() == pending.result()
        cancelled = fp.submit(f"{CALLS}:slow_files", str(tmp_path / "second"), 12, progress=lambda d, t: None)
        cancelled.cancel()
        assert process.ended and process._process.poll() is not None  # stopped and waited for
        written = sorted(p.name for p in (tmp_path / "second").glob("*.txt"))
        time.sleep(0.8)
        assert sorted(p.name for p in (tmp_path / "second").glob("*.txt")) == written  # nothing after
        assert len(written) < 12


def test_an_interrupt_while_waiting_stops_the_figures_before_it_goes_on(tmp_path):
    def progress(done, total):
        if done == 2:
            raise KeyboardInterrupt

    with fp.figure_process(f"{CALLS}:slow_files", start=True) as process:
        with pytest.raises(KeyboardInterrupt):
            fp.call(f"{CALLS}:slow_files", str(tmp_path), 20, progress=progress)
        assert process.ended and process._process.poll() is not None
        written = {p.name for p in tmp_path.glob("*.txt")}
        time.sleep(0.8)  # its workers (forked there) have gone too: nothing more is written
        assert {p.name for p in tmp_path.glob("*.txt")} == written
        assert 2 <= len(written) < 20
        assert fp.call("os:getpid") == os.getpid()  # later calls are drawn here


def test_a_call_cancelled_before_the_figure_process_took_it_is_never_run(tmp_path):
    with fp.figure_process("tests.reporting.slow_import:draw", f"{CALLS}:slow_files", start=True) as process:
        pending = fp.submit(f"{CALLS}:slow_files", str(tmp_path), 4)  # sent while it is still loading
        pending.cancel()
        assert process.ended and process._process.poll() is not None
    assert list(tmp_path.glob("*.txt")) == []


def test_the_figure_process_has_a_process_group_of_its_own_in_the_jobs_session():
    """The terminal's Ctrl-C (sent to the foreground process group) is the job's alone; the job's session,
    so that on Linux it is in the job's scheduler autogroup, where its nice-19 loading yields to the job
    (an autogroup of its own is given an equal share of the CPUs whatever its threads' nice)."""
    with fp.figure_process("os:getpid", start=True):
        helper = fp.call("os:getpid")
        assert os.getpgid(helper) == helper != os.getpgid(0)
        assert os.getsid(helper) == os.getsid(0)
        own = _autogroup("self")
        if own is not None:  # Linux with CONFIG_SCHED_AUTOGROUP, autogroups on
            assert _autogroup(helper) == own


def _autogroup(pid):
    """The name of the scheduler autogroup process `pid` is in ("/autogroup-17"), or None where the kernel
    shows none: no such file (no CONFIG_SCHED_AUTOGROUP), or an empty one (as on the CI machine: autogroups
    off, or the process in none of its own)."""
    try:
        words = Path(f"/proc/{pid}/autogroup").read_text().split()
    except FileNotFoundError:
        return None
    return words[0] if words else None


# the job in a terminal, as a shell runs it (the foreground process group), with stty tostop: the figure
# process, a background group of its session, writes to the terminal (a warning on stderr)
_TOSTOP = """
import os, sys, termios
attrs = termios.tcgetattr(2)
attrs[3] |= termios.TOSTOP
termios.tcsetattr(2, termios.TCSANOW, attrs)
os.tcsetpgrp(2, os.getpgrp())
from kalcal.reporting import figure_process as fp
with fp.figure_process("os:getpid", start=True):
    assert os.getpgid(fp.call("os:getpid")) != os.getpgrp()
    fp.call("warnings:warn", "written to the terminal by the figure process")
print("answered", flush=True)
"""


@pytest.mark.skipif(os.name != "posix", reason="a pseudo-terminal and process groups are POSIX's")
def test_the_figure_process_writes_to_a_tostop_terminal_without_being_stopped():
    import pty
    import select

    pid, terminal = pty.fork()
    if pid == 0:  # the child: a session of its own with the pseudo-terminal as its controlling terminal
        os.execv(sys.executable, [sys.executable, "-c", _TOSTOP])
    output, deadline = b"", time.monotonic() + 120  # a stopped figure process leaves the job waiting forever
    try:
        while time.monotonic() < deadline and b"answered" not in output:
            if select.select([terminal], [], [], 0.5)[0]:
                try:
                    output += os.read(terminal, 4096)
                except OSError:  # the child has ended and closed the terminal
                    break
    finally:
        if b"answered" not in output:
            os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        os.close(terminal)
    assert b"answered" in output, output.decode(errors="replace")
    assert b"written to the terminal by the figure process" in output


def test_a_stray_module_in_the_current_folder_does_not_reach_the_figure_process(tmp_path, monkeypatch):
    (tmp_path / "socket.py").write_text("raise ImportError('the current folder was imported from')\n")
    monkeypatch.chdir(tmp_path)
    with fp.figure_process("os:getpid", start=True):
        assert fp.call("os:getpid") != os.getpid()


def test_arguments_or_results_that_do_not_pickle_are_neither_lost_nor_fatal():
    with fp.figure_process(f"{CALLS}:pid_of", start=True):
        assert fp.call(f"{CALLS}:pid_of", lambda: None) == os.getpid()  # drawn here
        with pytest.raises(RuntimeError, match="unpicklable_result: its result could not be sent back"):
            fp.call(f"{CALLS}:unpicklable_result")
        assert fp.call("os:getpid") != os.getpid()  # the figure process is still there


@linux_only
def test_the_figure_process_dies_with_the_job_even_in_the_middle_of_a_call():
    code = (
        "import sys, time\n"
        "from kalcal.reporting import figure_process as fp\n"
        "with fp.figure_process('os:getpid', start=True):\n"
        "    print(fp.call('os:getpid'), flush=True)\n"
        "    fp.submit('time:sleep', 60)\n"  # busy there: it would not read its connection for a minute
        "    time.sleep(60)\n"
    )
    job = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        helper = int(job.stdout.readline())
        time.sleep(0.3)
        assert _alive(helper)
    finally:
        job.kill()
        job.wait()
    deadline = time.monotonic() + 10
    while _alive(helper) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _alive(helper)


@linux_only
def test_its_drawing_workers_die_with_it(tmp_path):
    with fp.figure_process(f"{CALLS}:slow_files", start=True) as process:
        fp.submit(f"{CALLS}:slow_files", str(tmp_path), 40)
        deadline = time.monotonic() + 30
        while len(list(tmp_path.glob("*.txt"))) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        process._process.kill()
        process._process.wait()
        time.sleep(0.1)
        written = {p.name: p.read_text() for p in tmp_path.glob("*.txt")}
        workers = {int(pid) for pid in written.values()}
        assert len(written) >= 2 and workers
        time.sleep(0.8)  # a worker left running would finish its figure in 0.3 s
        assert {p.name for p in tmp_path.glob("*.txt")} == set(written)
        assert not any(_alive(pid) for pid in workers)


def test_it_starts_only_where_it_helps(monkeypatch):
    import matplotlib  # noqa: F401 (this process has it: figures are drawn here, with its rcParams)

    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    monkeypatch.delenv("KALCAL_FIGURE_PROCESSES", raising=False)
    monkeypatch.setattr(fp, "_STARTED", False)
    assert not fp._helps()
    monkeypatch.delitem(sys.modules, "matplotlib")
    assert fp._helps()
    monkeypatch.setattr(fp, "_STARTED", True)  # this process has drawn through one already
    assert not fp._helps()
    monkeypatch.setattr(fp, "_STARTED", False)
    monkeypatch.setenv("KALCAL_FIGURE_PROCESSES", "1")  # draw in this process
    assert not fp._helps()
    monkeypatch.setenv("KALCAL_FIGURE_PROCESSES", "2")
    assert fp._helps()
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0})  # one CPU: nothing to overlap
    assert not fp._helps()
    with fp.figure_process("os:getpid") as process:
        assert process is None


def test_only_a_figure_process_that_drew_uses_up_the_process_s_one(monkeypatch):
    """A job that failed before drawing (a bad argument, a refused folder) leaves the one figure process
    for the next job; once one has drawn, the later jobs draw here."""
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    monkeypatch.delenv("KALCAL_FIGURE_PROCESSES", raising=False)
    monkeypatch.setattr(fp, "_STARTED", False)
    monkeypatch.delitem(sys.modules, "matplotlib", raising=False)
    with pytest.raises(DataError), fp.figure_process("os:getpid") as process:
        assert process is not None
        raise DataError("a bad log")
    assert not fp._STARTED
    with fp.figure_process("os:getpid") as process:
        assert fp.call("os:getpid") == process._process.pid  # drawn there
    assert fp._STARTED
    with fp.figure_process("os:getpid") as process:
        assert process is None and fp.call("os:getpid") == os.getpid()  # drawn here
    with fp.figure_process("os:getpid", start=True) as process:  # a caller that asks for one still has it
        assert process is not None


@pytest.mark.parametrize("call", ["fit", "noise", "sweep"])
def test_bad_arguments_are_refused_before_a_figure_process_starts(call, monkeypatch, tmp_path):
    import kalcal
    from kalcal.errors import KalcalError

    def refuse(*args, **kwargs):
        raise AssertionError("a figure process was started for a call its arguments refuse")

    monkeypatch.setattr(fp, "_helps", lambda: True)
    monkeypatch.setattr(fp, "FigureProcess", refuse)
    with pytest.raises(KalcalError):
        if call == "fit":
            kalcal.fit("accel-gps", gps=tmp_path / "gps.csv", out=tmp_path / "out")  # no --imu
        elif call == "noise":
            kalcal.noise(None, out=tmp_path / "out")
        else:
            kalcal.sweep("accel-gps", "filter.accel_noise_std", [0.01], out=tmp_path / "out")  # one value


def _loaded_after(args: list[str], env: dict | None = None) -> tuple[list[str], str]:
    code = (
        "import sys\n"
        f"sys.argv = ['kalcal', *{args!r}]\n"
        "from kalcal.cli import main\n"
        "try:\n    main()\nexcept SystemExit as exc:\n    assert not exc.code, exc.code\n"
        "print([m for m in ('matplotlib', 'xarray', 'pandas') if m in sys.modules])\n"
    )
    inherited = {key: value for key, value in os.environ.items() if key != "KALCAL_FIGURE_PROCESSES"}
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=600, env={**inherited, **(env or {})}
    )
    assert done.returncode == 0, done.stderr
    return eval(done.stdout.strip().splitlines()[-1]), done.stdout


SHORT_VERIFY = ["verify", "-n", "200", "--set", "scenario.duration=4", "--long-run", "0"]


@two_cpus
def test_kalcal_verify_draws_its_page_without_loading_matplotlib_or_xarray_the_same_bytes(tmp_path):
    """The job sends its statistics as numpy parts, and the figures draw them as they are: neither the job's
    process nor the drawing loads xarray or pandas (drawn in the job's process, only matplotlib is added)."""
    loaded, _ = _loaded_after([*SHORT_VERIFY, "--out", str(tmp_path / "there")])
    assert loaded == []  # every figure was drawn in the figure process
    here, _ = _loaded_after([*SHORT_VERIFY, "--out", str(tmp_path / "here")], {"KALCAL_FIGURE_PROCESSES": "1"})
    assert here == ["matplotlib"]
    there = sorted((tmp_path / "there" / "figures").glob("*.png"))
    assert len(there) >= 10
    for path in there:
        assert path.read_bytes() == (tmp_path / "here" / "figures" / path.name).read_bytes(), path.name
    drawn = {path.name: path.read_bytes() for path in there}
    redrawn, _ = _loaded_after(["report", str(tmp_path / "here")])  # kalcal report: the same, there too
    assert redrawn == []  # it reads stats.nc as numpy parts, without xarray; it draws in the figure process
    assert {path.name: path.read_bytes() for path in (tmp_path / "here" / "figures").glob("*.png")} == drawn


@two_cpus
def test_kalcal_calibrate_draws_its_figure_without_loading_matplotlib_the_same_bytes(tmp_path):
    logs = tmp_path / "logs"
    simulated = subprocess.run(
        [sys.executable, "-m", "kalcal", "simulate", "accel-gps", "--seed", "3", "--set", "scenario.duration=60",
         "--out", str(logs)], capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert simulated.returncode == 0, simulated.stderr
    args = ["calibrate", "accel-gps", "--imu", str(logs / "imu.csv"), "--gps", str(logs / "gps.csv")]
    loaded, _ = _loaded_after([*args, "--out", str(tmp_path / "there")])
    assert loaded == ["pandas"]  # the logs are read with pandas; matplotlib stays in the figure process
    _loaded_after([*args, "--out", str(tmp_path / "here")], {"KALCAL_FIGURE_PROCESSES": "1"})
    figure = (tmp_path / "there" / "calibration.png").read_bytes()
    assert figure == (tmp_path / "here" / "calibration.png").read_bytes()


@linux_only
def test_the_imports_run_at_the_lowest_priority_and_the_drawing_at_the_process_s(monkeypatch):
    import importlib
    import threading

    own = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
    seen = []
    monkeypatch.setattr(
        importlib, "import_module", lambda name: seen.append(os.getpriority(os.PRIO_PROCESS, threading.get_native_id()))
    )
    assert fp._load(("a", "b"))
    assert seen == [19, 19]
    assert os.getpriority(os.PRIO_PROCESS, threading.get_native_id()) == own  # the thread that forks the workers


def test_the_figure_process_loads_neither_xarray_nor_pandas_nor_scipy_linalg():
    """What the figure process imports for the jobs' figures (the page's, a calibration's and a fit's): half
    a second of xarray and pandas less on a core the job's Monte Carlo is using, scipy.linalg (which the
    steady state it unpickles needs only to be solved, in the job), and numba, which a fit's figure would
    load through the fitting code."""
    code = (
        "import sys\n"
        "import kalcal.reporting.figures, kalcal.plots.calibration, kalcal.plots.fit\n"
        "print(sorted(m for m in ('xarray', 'pandas', 'dask', 'scipy.linalg', 'numba') if m in sys.modules))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "[]"


class _Process:
    def __init__(self, busy=False, ended=False):
        self.busy, self.ended = busy, ended


@pytest.mark.parametrize(("process", "expected"), [(None, False), (_Process(), True), (_Process(busy=True), False),
                                                   (_Process(ended=True), False)])  # fmt: skip
def test_a_call_goes_to_the_figure_process_only_when_it_is_there_idle_and_alive(process, expected):
    """A busy process would answer another call's messages; an ended one none: the call is drawn here."""
    token = fp._CURRENT.set(process)
    try:
        assert fp.elsewhere() is expected
    finally:
        fp._CURRENT.reset(token)


def test_a_send_interrupted_once_busy_stops_the_figure_process_before_the_interrupt_goes_on(monkeypatch):
    """Ctrl-C in the job while it sends a call: the process, busy from before the send, is stopped and
    waited for before the interrupt goes on, so that it draws nothing after the job's outputs are cleaned."""
    with fp.figure_process("os:getpid", start=True) as process:
        fp.call("os:getpid")  # loaded, idle

        def interrupted(message):
            raise KeyboardInterrupt

        monkeypatch.setattr(process._connection, "send_bytes", interrupted)
        with pytest.raises(KeyboardInterrupt):
            fp.submit("os:getpid")
        assert process.ended and not process.busy and process._process.poll() is not None


def _stopped_before_cleanup(figure: str, save, out: Path) -> None:
    """``save(out)`` fails writing its files while the figure process draws ``figure``: the figure is
    stopped and waited for before the outputs are cleaned up, so the folder the run created is gone and
    nothing is written into it later (the process has ended before the error reaches here)."""
    with fp.figure_process(figure, start=True) as process:
        fp.call("os:getpid")  # loaded: the figure is taken at once
        with pytest.raises(Exception, match="No space left on device"):
            save(out)
        assert process.ended and process._process.poll() is not None
        assert not out.exists()
        time.sleep(1.0)
    assert not out.exists()


def test_a_calibration_whose_files_fail_waits_for_its_figure_and_leaves_no_outputs(tmp_path, monkeypatch):
    """estimates.csv cannot be written while the figure process draws calibration.png: the figure is
    stopped and waited for before the outputs are cleaned up, so the folder this first run created is gone
    and nothing is written into it later."""
    import kalcal
    from kalcal.jobs import calibrate as calibrate_job
    from kalcal.jobs.calibrate import compute_accel_gps_calibration, save_calibration
    from kalcal.models.registry import build_scenario

    scenario = build_scenario("accel-gps", None, ["scenario.duration=60"])
    logs = kalcal.simulate(scenario, 3, out=tmp_path / "logs").paths
    calibration = compute_accel_gps_calibration(scenario, logs["imu"], logs["gps"])

    def full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(calibrate_job, "write_csv", full)
    _stopped_before_cleanup(names.CALIBRATION_FIGURE, lambda out: save_calibration(calibration, out), tmp_path / "out")


@pytest.fixture(scope="module")
def minute_logs(tmp_path_factory):
    """A simulated minute of accel-gps logs (CSV), for the commands that read logs."""
    logs = tmp_path_factory.mktemp("logs")
    simulated = subprocess.run(
        [sys.executable, "-m", "kalcal", "simulate", "accel-gps", "--seed", "3", "--set", "scenario.duration=60",
         "--out", str(logs)], capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert simulated.returncode == 0, simulated.stderr
    return logs


@two_cpus
def test_kalcal_fit_draws_its_figure_without_loading_matplotlib_the_same_bytes(tmp_path, minute_logs):
    """fit.png is drawn in the figure process, loaded while the fit runs: the job never imports matplotlib,
    and the figure is the bytes the job's own process draws."""
    args = ["fit", "accel-gps", "--imu", str(minute_logs / "imu.csv"), "--gps", str(minute_logs / "gps.csv")]
    loaded, _ = _loaded_after([*args, "--out", str(tmp_path / "there")])
    assert loaded == ["pandas"]  # the logs are read with pandas; matplotlib stays in the figure process
    here, _ = _loaded_after([*args, "--out", str(tmp_path / "here")], {"KALCAL_FIGURE_PROCESSES": "1"})
    assert here == ["matplotlib", "pandas"]
    assert (tmp_path / "there" / "fit.png").read_bytes() == (tmp_path / "here" / "fit.png").read_bytes()


def test_a_fit_without_out_draws_nothing_and_starts_no_figure_process(minute_logs, monkeypatch):
    import kalcal

    def refuse(*args, **kwargs):
        raise AssertionError("a figure process was started for a fit that writes nothing")

    monkeypatch.setattr(fp, "_helps", lambda: True)  # where one would help, were there a figure to draw
    monkeypatch.setattr(fp, "FigureProcess", refuse)
    result = kalcal.fit("accel-gps", imu=minute_logs / "imu.csv", gps=minute_logs / "gps.csv")
    assert result.paths == {}


def test_a_fit_whose_files_fail_waits_for_its_figure_and_leaves_no_outputs(tmp_path, monkeypatch, minute_logs):
    """fit.json cannot be written while the figure process draws fit.png: as a calibration's, the figure is
    stopped and waited for before the outputs are cleaned up."""
    import kalcal.jobs.fit as fit_job
    from kalcal.models.registry import build_scenario

    scenario = build_scenario("accel-gps", None, ["scenario.integration=trapezoid"])
    run = fit_job.compute_accel_gps_fit(scenario, minute_logs / "imu.csv", minute_logs / "gps.csv")

    def full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(fit_job, "write_json", full)
    _stopped_before_cleanup(names.FIT_FIGURE, lambda out: fit_job.save_fit(run, out), tmp_path / "out")


@pytest.fixture(scope="module")
def static_csv(tmp_path_factory):
    """A static accelerometer log (white noise at 100 Hz) as CSV, for ``kalcal noise``."""
    import numpy as np

    path = tmp_path_factory.mktemp("static") / "imu.csv"
    accel = np.random.default_rng(0).normal(0.05, 0.02, 2**15)
    path.write_text("time,accel\n" + "\n".join(f"{i / 100.0!r},{a!r}" for i, a in enumerate(accel.tolist())) + "\n")
    return path


@two_cpus
def test_kalcal_noise_draws_its_figure_without_loading_matplotlib_the_same_bytes(tmp_path, static_csv):
    """allan.png is drawn in the figure process, loaded while the log is read and identified."""
    args = ["noise", "--imu", str(static_csv)]
    loaded, _ = _loaded_after([*args, "--out", str(tmp_path / "there")])
    assert loaded == ["pandas"]
    here, _ = _loaded_after([*args, "--out", str(tmp_path / "here")], {"KALCAL_FIGURE_PROCESSES": "1"})
    assert here == ["matplotlib", "pandas"]
    assert (tmp_path / "there" / "allan.png").read_bytes() == (tmp_path / "here" / "allan.png").read_bytes()


def test_a_noise_run_whose_files_fail_waits_for_its_figure_and_leaves_no_outputs(tmp_path, monkeypatch, static_csv):
    import kalcal.jobs.noise as noise_job

    run = noise_job.compute_noise(static_csv)

    def full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(noise_job, "write_json", full)
    _stopped_before_cleanup(names.NOISE_FIGURE, lambda out: noise_job.save_noise(run, out), tmp_path / "out")


@two_cpus
def test_kalcal_analyze_draws_its_figures_without_loading_matplotlib_the_same_bytes(tmp_path):
    loaded, _ = _loaded_after(["analyze", "--out", str(tmp_path / "there")])
    assert loaded == []  # nor xarray nor pandas: analysis.nc is written from numpy parts
    here, _ = _loaded_after(["analyze", "--out", str(tmp_path / "here")], {"KALCAL_FIGURE_PROCESSES": "1"})
    assert here == ["matplotlib"]
    for name in ("sigma.png", "budget.png"):
        assert (tmp_path / "there" / "figures" / name).read_bytes() == (tmp_path / "here" / "figures" / name).read_bytes()
    assert (tmp_path / "there" / "analysis.nc").read_bytes() == (tmp_path / "here" / "analysis.nc").read_bytes()


def test_an_analysis_whose_files_fail_waits_for_its_figures_and_leaves_no_outputs(tmp_path, monkeypatch):
    import kalcal
    import kalcal.io.results

    result = kalcal.analyze("accel-gps", {"scenario.duration": 10})

    def full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(kalcal.io.results, "write_json", full)
    _stopped_before_cleanup(names.ANALYSIS_FIGURES, result.save, tmp_path / "out")


@two_cpus
def test_kalcal_sweep_draws_its_figure_without_loading_matplotlib_the_same_bytes(tmp_path):
    args = ["sweep", "-n", "300", "--set", "scenario.duration=4", "--set", "filter.accel_noise_std=0.01,0.04"]
    loaded, _ = _loaded_after([*args, "--out", str(tmp_path / "there")])
    assert "matplotlib" not in loaded  # pandas holds the table; xarray the runs' statistics, if they load it
    here, _ = _loaded_after([*args, "--out", str(tmp_path / "here")], {"KALCAL_FIGURE_PROCESSES": "1"})
    assert "matplotlib" in here
    assert (tmp_path / "there" / "sweep.png").read_bytes() == (tmp_path / "here" / "sweep.png").read_bytes()


@two_cpus
def test_a_process_starts_one_figure_process_and_later_calls_draw_here(minute_logs, tmp_path):
    """A script that fits in a loop: the first call draws in a figure process, the later ones here (the
    second loads matplotlib once), rather than a figure process each loading it again; the same figure."""
    code = (
        "import sys, kalcal\n"
        "from kalcal.reporting import figure_process as fp\n"
        "started, real = [], fp.FigureProcess.__init__\n"
        "fp.FigureProcess.__init__ = lambda self, *a: started.append(1) or real(self, *a)\n"
        "loaded = []\n"
        "for i in range(3):\n"
        f"    kalcal.fit('accel-gps', imu={str(minute_logs / 'imu.csv')!r}, gps={str(minute_logs / 'gps.csv')!r},\n"
        f"               out={str(tmp_path)!r} + f'/fit{{i}}')\n"
        "    loaded.append('matplotlib' in sys.modules)\n"
        "print([len(started), loaded])\n"
    )
    inherited = {key: value for key, value in os.environ.items() if key != "KALCAL_FIGURE_PROCESSES"}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, env=inherited)
    assert done.returncode == 0, done.stderr
    assert eval(done.stdout.strip().splitlines()[-1]) == [1, [False, True, True]]
    first = (tmp_path / "fit0" / "fit.png").read_bytes()
    assert (tmp_path / "fit1" / "fit.png").read_bytes() == first == (tmp_path / "fit2" / "fit.png").read_bytes()


def test_the_fit_names_the_latency_as_searched_on_a_linear_scale(minute_logs, tmp_path, monkeypatch):
    """save_fit hands the figure accel-gps's linearly searched settings (the latency), scale-bias none."""
    import kalcal
    import kalcal.jobs.fit as fit_job
    from kalcal.fitting.accel_gps import LINEAR

    sent, real = [], fit_job.submit
    monkeypatch.setattr(fit_job, "submit", lambda *a, **k: sent.append(k["linear"]) or real(*a, **k))
    kalcal.fit("accel-gps", imu=minute_logs / "imu.csv", gps=minute_logs / "gps.csv", out=tmp_path / "accel")
    rows = "\n".join(f"{0.1 * i!r},{1.01 * (i % 7) + 0.1 + 0.01 * ((i * 37) % 11 - 5)!r}" for i in range(200))
    (tmp_path / "log.csv").write_text("reference,sensor\n" + rows + "\n")
    kalcal.fit("scale-bias", data=tmp_path / "log.csv", out=tmp_path / "sb")
    assert sent == [tuple(LINEAR), ()] and "filter.gps_latency" in LINEAR
