"""How the console script ends (:func:`kalcal.cli.run`): main's status and one line, through Python's own exit."""

from __future__ import annotations

import subprocess
import sys

import pytest


@pytest.mark.parametrize(
    ("args", "status"),
    [(["--version"], 0), (["--help"], 0), (["verify", "-n", "5", "--no-report"], 2), (["verify", "--no-such-option"], 2)],
)
def test_the_console_script_keeps_main_s_exit_status_and_its_one_line(args, status):
    ran = subprocess.run([sys.executable, "-m", "kalcal", *args], capture_output=True, text=True, timeout=300)
    assert ran.returncode == status and "Traceback" not in ran.stderr, ran.stdout + ran.stderr
    if status:
        assert ran.stderr.startswith("kalcal: error: ") and len(ran.stderr.strip().splitlines()) == 1, ran.stderr


def test_the_exit_handlers_and_the_interpreter_s_teardown_run_and_threads_are_waited_for(tmp_path):
    marker = tmp_path / "thread-done"
    code = (
        "import atexit, sys, threading, time\n"
        "class Teardown:\n    def __del__(self):\n        sys.stdout.write('teardown\\n')\n        sys.stdout.flush()\n"
        "keep = Teardown()\n"
        "atexit.register(lambda: print('exit handler', flush=True))\n"
        f"def work():\n    time.sleep(0.5)\n    open({str(marker)!r}, 'w').close()\n"
        "threading.Thread(target=work).start()\n"
        "sys.argv = ['kalcal', '--version']\n"
        "from kalcal.cli import run\nrun()\n"
    )
    ran = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert ran.returncode == 0, ran.stderr
    assert {"exit handler", "teardown"} <= set(ran.stdout.splitlines()), ran.stdout
    assert marker.is_file(), "the process ended before its non-daemon thread finished"
