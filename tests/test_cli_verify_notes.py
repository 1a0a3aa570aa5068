"""``kalcal verify`` passes its notes through: the estimated wall time and a Dask worker's loss reach the
terminal as ``kalcal: note:`` lines, through the command, ``kalcal.verify`` and the cluster.

A real command in a real process: the notes are printed by the command's own callback
(``cli/verify.py`` -> ``api/verify.py`` -> the estimate check and :func:`~kalcal.montecarlo.distributed.dask_client`),
so leaving either argument out on the way fails this test.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from kalcal.montecarlo.distributed import WORKER_LOST


def _children(pid: int) -> list[int]:
    """The child processes of ``pid`` (Linux's /proc)."""
    found = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            found += [int(child) for child in (task / "children").read_text().split()]
        except OSError:
            pass
    return found


def _worker_pids(pid: int) -> list[int]:
    """The local cluster's worker processes: the children started by multiprocessing's spawn."""
    workers = []
    for child in _children(pid):
        try:
            if b"spawn_main" in Path(f"/proc/{child}/cmdline").read_bytes():
                workers.append(child)
        except OSError:
            pass
    return workers


def test_verify_prints_the_estimate_and_a_lost_worker_as_notes(tmp_path):
    """A trillion realizations on 2 workers with a checkpoint (so not refused): the estimate note comes
    half a second into the Monte Carlo; a worker then SIGKILLed is one note; Ctrl-C ends it in one line."""
    command = [
        sys.executable, "-m", "kalcal", "verify", "-n", "1000000000000", "--workers", "2", "--no-report",
        "--long-run", "0", "--checkpoint", str(tmp_path / "run.ckpt"), "--out", str(tmp_path / "out"),
    ]  # fmt: skip
    process = subprocess.Popen(
        command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, start_new_session=True,
        env={**os.environ, "COLUMNS": "400"},
    )  # fmt: skip
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(iter(process.stderr.readline, "")), daemon=True)
    reader.start()

    def wait_for(prefix: str, within: float) -> None:
        deadline = time.monotonic() + within
        while not any(line.startswith(prefix) for line in lines):
            assert process.poll() is None and time.monotonic() < deadline, (prefix, lines)
            time.sleep(0.05)

    try:
        wait_for("kalcal: note: estimated wall time of the Monte Carlo: ", 180)
        workers = _worker_pids(process.pid)
        assert len(workers) == 2, workers
        os.kill(workers[0], signal.SIGKILL)
        wait_for(f"kalcal: note: {WORKER_LOST}", 60)
        # the nanny starts a new worker process; it is Ctrl-C'd once it runs (not while it imports: see
        # the module docstring of kalcal.montecarlo.distributed)
        deadline = time.monotonic() + 60
        while len([pid for pid in _worker_pids(process.pid) if pid != workers[0]]) < 2:
            assert time.monotonic() < deadline, "no worker was started in the lost one's place"
            time.sleep(0.1)
        time.sleep(5.0)
        os.killpg(process.pid, signal.SIGINT)
        process.wait(timeout=60)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
    reader.join(timeout=10)
    assert process.returncode == 130, lines
    assert len(lines) == 3, "".join(lines)
    assert lines[0].startswith("kalcal: note: estimated wall time of the Monte Carlo: ") and "Dask threads)" in lines[0]
    assert lines[1:] == [f"kalcal: note: {WORKER_LOST}\n", "kalcal: interrupted\n"]
