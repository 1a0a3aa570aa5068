"""How the console script ends (:func:`kalcal.cli.run`): main's status, the exit handlers run, the
streams flushed, the interpreter's teardown skipped, and Python's own exit kept where it matters."""

from __future__ import annotations

import subprocess
import sys

import pytest

# A child that runs the command line as the console script does. Its module global ``keep`` is freed
# only by the interpreter's teardown, whose __del__ says so; the exit handler is atexit's.
CHILD = """
import atexit, sys
class Teardown:
    def __del__(self):
        sys.stdout.write("teardown\\n")
        sys.stdout.flush()
keep = Teardown()
atexit.register(lambda: print("exit handler", flush=True))
sys.argv = ["kalcal", *sys.argv[2:]]
from kalcal.cli import main, run
if sys.argv_entry == "run":
    run()
else:
    main()
"""


def _child(entry: str, *args: str, prefix: tuple[str, ...] = ()) -> subprocess.CompletedProcess:
    code = CHILD.replace("sys.argv_entry", repr(entry))
    return subprocess.run(
        [sys.executable, *prefix, "-c", code, entry, *args], capture_output=True, text=True, timeout=300
    )


def test_the_console_script_runs_the_exit_handlers_and_skips_the_teardown():
    ran = _child("run", "--version")
    assert ran.returncode == 0, ran.stderr
    lines = ran.stdout.splitlines()
    assert lines[0].startswith("kalcal ") and "exit handler" in lines and "teardown" not in lines, ran.stdout
    # the control: main() alone ends through Python's exit, whose teardown frees the global
    plain = _child("main", "--version")
    assert plain.returncode == 0 and "teardown" in plain.stdout.splitlines(), plain.stdout + plain.stderr


@pytest.mark.parametrize(
    ("args", "status"),
    [(["--version"], 0), (["verify", "-n", "5", "--no-report"], 2), (["verify", "--no-such-option"], 2)],
)
def test_the_console_script_keeps_main_s_exit_status_and_its_one_line(args, status):
    ran = subprocess.run([sys.executable, "-m", "kalcal", *args], capture_output=True, text=True, timeout=300)
    assert ran.returncode == status, ran.stdout + ran.stderr
    if status:
        assert ran.stderr.startswith("kalcal: error: ") and len(ran.stderr.strip().splitlines()) == 1, ran.stderr


def test_under_a_profiler_python_s_own_exit_writes_the_profile(tmp_path):
    profile = tmp_path / "kalcal.prof"
    ran = subprocess.run(
        [sys.executable, "-m", "cProfile", "-o", str(profile), "-m", "kalcal", "--version"],
        capture_output=True, text=True, timeout=300,
    )
    assert ran.returncode == 0 and ran.stdout.startswith("kalcal "), ran.stdout + ran.stderr
    assert profile.is_file() and profile.stat().st_size > 0


def test_a_thread_still_running_is_waited_for_as_python_does(tmp_path):
    marker = tmp_path / "thread-done"
    code = (
        "import sys, threading, time\n"
        f"def work():\n    time.sleep(0.5)\n    open({str(marker)!r}, 'w').close()\n"
        "threading.Thread(target=work).start()\n"
        "sys.argv = ['kalcal', '--version']\n"
        "from kalcal.cli import run\nrun()\n"
    )
    ran = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert ran.returncode == 0, ran.stderr
    assert marker.is_file(), "the process ended before its non-daemon thread finished"


def test_a_message_status_is_printed_and_exits_one():
    code = (
        "import sys\nfrom kalcal import cli\n"
        "def main():\n    print('partial line', end='')\n    sys.exit('kalcal: a message')\n"
        "cli.main = main\ncli.run()\n"
    )
    ran = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert ran.returncode == 1 and ran.stdout == "partial line", ran.stdout  # unflushed output still written
    assert ran.stderr.strip() == "kalcal: a message"


def test_a_stream_that_cannot_be_flushed_takes_python_s_own_exit():
    """stdout a pipe whose reader has gone: the flush fails, so the process leaves through Python's own
    exit, which reports the broken pipe and exits 120, as a plain Python program does."""
    code = (
        "import os, sys\nfrom kalcal import cli\n"
        "read, write = os.pipe()\nos.close(read)\n"  # a pipe with no reader left
        "sys.stdout = open(write, 'w', buffering=1 << 16)\n"
        "def main():\n    print('x' * 100)\n"  # buffered: written only by the flush at the end
        "cli.main = main\ncli.run()\n"
    )
    ran = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    plain = subprocess.run(
        [sys.executable, "-c", code.replace("from kalcal import cli\n", "").replace("cli.main = main\ncli.run()\n", "main()\n")],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert plain.returncode == 120, plain.stderr  # Python's own exit, for comparison
    assert ran.returncode == 120, ran.stderr
    assert "BrokenPipeError" in ran.stderr or "Broken pipe" in ran.stderr, ran.stderr


def test_a_fits_idle_evaluation_threads_do_not_keep_the_teardown():
    """The threads a fit keeps for its evaluations (kalcal.fitting.local_search) are idle once the command
    is done: the console script still skips the teardown."""
    code = CHILD.replace(
        "from kalcal.cli import main, run\n",
        "import time\nimport numpy as np\nfrom kalcal.fitting import local_search\n"
        "def slow(point):\n    time.sleep(0.003)\n    return float(point[0])\n"
        "assert local_search.evaluate_all(slow, [np.array([float(i)]) for i in range(4)], workers=2) == [0.0, 1.0, 2.0, 3.0]\n"
        "from kalcal.cli import main, run\n",
    ).replace("sys.argv_entry", repr("run"))
    ran = subprocess.run([sys.executable, "-c", code, "run", "--version"], capture_output=True, text=True, timeout=300)
    assert ran.returncode == 0, ran.stderr
    lines = ran.stdout.splitlines()
    assert "exit handler" in lines and "teardown" not in lines, ran.stdout
