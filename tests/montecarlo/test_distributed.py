"""Scale-out on Dask: a local cluster gives the numbers of a plain run, and survives a killed worker.

Dask is a dependency of kalcal, so a missing ``distributed`` is an error here, not a skip.
"""

import os
import signal

import distributed
import pytest

from kalcal.models.accel_gps import AccelGpsScenario
from kalcal.models.config import apply_settings
from kalcal.montecarlo.engine import run_monte_carlo
from kalcal.montecarlo.scenarios import accel_gps_problem
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
