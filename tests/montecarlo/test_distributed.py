"""Scale-out on Dask: a local cluster gives the numbers of a plain run, and survives a killed worker.

Dask is a dependency of kalcal, so a missing ``distributed`` is an error here, not a skip.
"""

import os
import signal

import distributed
import pytest

from kalcal.scenarios.accel_gps.settings import AccelGpsScenario
from kalcal.models.config import apply_settings
from kalcal.montecarlo.engine import run_monte_carlo
from kalcal.scenarios.accel_gps.problem import accel_gps_problem
from tests._helpers import sums_equal


def _problem():
    return accel_gps_problem(apply_settings(AccelGpsScenario(), {"scenario.duration": 4.0}))


@pytest.fixture(scope="module")
def client():
    with (
        distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster,
        distributed.Client(cluster) as c,
    ):
        yield c


def test_dask_cluster_gives_the_numbers_of_a_plain_run(client):
    problem = _problem()
    plain = run_monte_carlo(problem, 10_000, seed=8, block_size=1000, workers=1)
    on_dask = run_monte_carlo(problem, 10_000, seed=8, block_size=1000, client=client)
    batched = run_monte_carlo(problem, 10_000, seed=8, block_size=1000, client=client, blocks_per_task=3)
    assert sums_equal(plain.sums, on_dask.sums) and sums_equal(plain.sums, batched.sums)


def test_a_killed_worker_has_its_blocks_rerun(client):
    """SIGKILL one of the two workers once a third of the blocks are in; the run still completes, equal."""
    problem = accel_gps_problem(AccelGpsScenario())
    plain = run_monte_carlo(problem, 60_000, seed=3, block_size=1000, workers=2)
    pids = list(client.run(os.getpid).values())
    killed = []

    def kill_one_worker(done, total):
        if not killed and total / 3 <= done < total:
            os.kill(pids[0], signal.SIGKILL)
            killed.append(done)

    run = run_monte_carlo(problem, 60_000, seed=3, block_size=1000, client=client, progress=kill_one_worker)
    assert killed, "the run ended before a worker could be killed"
    assert sums_equal(plain.sums, run.sums)


def test_a_local_cluster_keeps_distributeds_warnings_off_stderr():
    """Another cluster on the dashboard's port 8787: distributed warns and moves; kalcal's user sees nothing."""
    import socket
    import warnings

    from kalcal.montecarlo.distributed import dask_client

    holder = socket.socket()
    try:
        holder.bind(("", 8787))
        holder.listen()
    except OSError:
        pass  # already taken by another process: the same situation
    try:
        with warnings.catch_warnings(record=True) as seen:
            warnings.simplefilter("always")
            with dask_client(1) as client:
                assert client.submit(sum, [1, 2]).result() == 3
    finally:
        holder.close()
    raw = [str(w.message) for w in seen if issubclass(w.category, UserWarning) and "distributed" in w.filename]
    assert raw == []


KILL_SCRIPT = """
import os, signal, sys
from kalcal.cli._common import print_note
from kalcal.scenarios.accel_gps.settings import AccelGpsScenario
from kalcal.montecarlo.distributed import dask_client
from kalcal.montecarlo.engine import run_monte_carlo
from kalcal.scenarios.accel_gps.problem import accel_gps_problem

if __name__ == "__main__":
    problem = accel_gps_problem(AccelGpsScenario())
    with dask_client(2, notes=print_note) as client:
        pids = list(client.run(os.getpid).values())
        killed = []

        def kill_one_worker(done, total):
            if not killed and total / 3 <= done < total:
                os.kill(pids[0], signal.SIGKILL)
                killed.append(done)

        run_monte_carlo(problem, 60_000, seed=3, block_size=1000, client=client, progress=kill_one_worker)
    print("killed" if killed else "not killed")
"""


def test_a_killed_workers_log_lines_are_one_note(tmp_path):
    """A real worker SIGKILLed mid-run: distributed logs the loss from the scheduler, the client and the
    nanny (4 lines on 2114039, 'distributed.nanny - WARNING - Restarting worker' among them, in an order
    that varies from run to run); the user sees exactly one line, the same whichever record came first."""
    import subprocess
    import sys

    from kalcal.montecarlo.distributed import WORKER_LOST

    script = tmp_path / "kill.py"
    script.write_text(KILL_SCRIPT, encoding="utf-8")
    process = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=300, env={**os.environ, "COLUMNS": "400"}
    )
    assert process.returncode == 0, process.stderr[-3000:]
    assert process.stdout.strip() == "killed"
    assert process.stderr.strip().splitlines() == [f"kalcal: note: {WORKER_LOST}"]


def _handler_and_record():
    import logging

    from kalcal.montecarlo.distributed import NoteHandler

    notes = []
    handler = NoteHandler(notes.append)

    def record(message, at, name="distributed.scheduler", level=logging.WARNING):
        made = logging.LogRecord(name, level, __file__, 1, message, None, None)
        made.created = at
        handler.handle(made)

    return notes, record


def test_log_records_close_together_are_one_event():
    import logging

    from kalcal.montecarlo.distributed import EVENT_WINDOW_S, WORKER_LOST

    notes, record = _handler_and_record()
    record("Removing worker 'tcp://127.0.0.1:1' caused the cluster to lose already computed task(s)", 100.0)
    record("Couldn't gather keys", 100.01, level=logging.ERROR)
    record("Restarting worker (status=Status.running)", 100.02, "distributed.nanny")
    record("Restarting worker (status=Status.running)", 100.03 + EVENT_WINDOW_S, "distributed.nanny")
    record("Unmanaged memory use is high\nmore", 200.0, "distributed.worker.memory")
    assert notes == [
        WORKER_LOST,
        WORKER_LOST,
        "Dask (distributed.worker.memory, warning): Unmanaged memory use is high",
    ]


@pytest.mark.parametrize(
    "first",
    [
        ("distributed.scheduler", "Couldn't gather keys: {'block_task-1b3f': 'memory'}"),
        ("distributed.client", "Couldn't gather 1 keys, rescheduling ('block_task-1b3f',)"),
        ("distributed.nanny", "Restarting worker (status=Status.running)"),
        ("distributed.nanny", "Worker process 4242 was killed by signal 9"),
    ],
)
def test_a_lost_worker_is_named_whichever_record_comes_first(first):
    """The orders seen when a real worker was killed: the scheduler's "Couldn't gather keys: {...:
    'memory'}" first gave a note that read as a memory error; every record of the loss names the loss."""
    import logging

    from kalcal.montecarlo.distributed import WORKER_LOST

    notes, record = _handler_and_record()
    record(first[1], 50.0, first[0], level=logging.ERROR)
    record("Removing worker 'tcp://127.0.0.1:1' caused the cluster to lose already computed task(s)", 50.01)
    record("Restarting worker (status=Status.running)", 50.02, "distributed.nanny")
    assert notes == [WORKER_LOST]


def test_a_steady_stream_of_records_is_not_one_event():
    """Records a second apart for 20 s are 4 notes (one per window counted from an event's first record),
    and a worker lost among them is noted: the window once ran from the last record, making the stream one
    note and the loss none."""
    from kalcal.montecarlo.distributed import EVENT_WINDOW_S, WORKER_LOST

    notes, record = _handler_and_record()
    for second in range(20):
        record("Unmanaged memory use is high", 10.0 + second, "distributed.worker.memory")
        if second == 12:
            record("Restarting worker (status=Status.running)", 10.5 + second, "distributed.nanny")
    memory = "Dask (distributed.worker.memory, warning): Unmanaged memory use is high"
    assert EVENT_WINDOW_S == 5.0  # the count below is for this window
    assert notes == [memory, memory, memory, WORKER_LOST, memory]  # at 10, 16, 22, 22.5 and 28 s


def test_an_error_after_a_warning_is_a_note_of_its_own():
    """Other records are grouped by logger and level: an ERROR 1 s after a memory WARNING (within the
    window) once fell into the warning's event and was never shown; a second warning of the same logger
    inside the window is still one event."""
    import logging

    notes, record = _handler_and_record()
    record("Unmanaged memory use is high", 10.0, "distributed.worker.memory")
    record("Unmanaged memory use is high", 10.5, "distributed.worker.memory")
    record("Task exceeded its memory budget", 11.0, "distributed.worker.memory", level=logging.ERROR)
    record("Scheduler lost contact", 11.5, "distributed.client", level=logging.ERROR)
    assert notes == [
        "Dask (distributed.worker.memory, warning): Unmanaged memory use is high",
        "Dask (distributed.worker.memory, error): Task exceeded its memory budget",
        "Dask (distributed.client, error): Scheduler lost contact",
    ]
