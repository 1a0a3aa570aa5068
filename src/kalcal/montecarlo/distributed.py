"""Dask as the scale-out engine: a local cluster of processes or an existing scheduler.

The engine submits blocks of realizations as Dask tasks (:func:`kalcal.montecarlo.engine.block_task`)
and folds their sums in block order, so the numbers do not depend on the cluster. A worker that dies
mid-task has its task rerun by the scheduler on another worker. The local cluster's worker processes
ignore SIGINT: a Ctrl-C stops the run (one line, ``kalcal: interrupted``) and this process closes them.
Dask (``dask[distributed]``) is a
default dependency of kalcal.
"""

from __future__ import annotations

import contextlib
import logging
import signal
import threading
import warnings
from collections.abc import Iterator

from kalcal.errors import ConfigError
from kalcal.interrupts import Interrupted


@contextlib.contextmanager
def _quiet_distributed() -> Iterator[None]:
    """distributed's own UserWarnings (the dashboard's port 8787 taken by another cluster, so it moves to
    a free one) say nothing about the run: kept off the user's stderr while the cluster lives."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", category=UserWarning, module=r"distributed(\.|$)")
        yield


@contextlib.contextmanager
def dask_client(workers: int | None = None, scheduler: str | None = None) -> Iterator[object | None]:
    """A ``dask.distributed.Client``: on ``scheduler`` if given, else on a new local cluster of ``workers``
    single-threaded processes; None when neither is asked for (the engine then uses local threads)."""
    if workers is None and scheduler is None:
        yield None
        return
    if workers is not None and scheduler is not None:
        raise ConfigError("--workers starts a local cluster and --scheduler uses an existing one: give one of them")
    if workers is not None and workers < 1:
        raise ConfigError(f"--workers: expected a positive number of processes, got {workers}")
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise ConfigError("--workers/--scheduler need Dask, a dependency of kalcal: pip install 'dask[distributed]'") from None
    if scheduler is not None:
        try:
            client = Client(scheduler, timeout="10s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise ConfigError(f"--scheduler {scheduler}: cannot connect ({exc})") from None
        with client:
            yield client
        return
    # the worker processes start with SIGINT ignored: Ctrl-C (sent to the whole process group) stops this
    # process, which then closes the cluster, instead of every worker printing its own traceback
    with _sigint_ignored(), _quiet_distributed():
        cluster = LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            # no dashboard, and the scheduler's HTTP server on a free port: on its default, 8787, a second
            # run at the same time printed a warning that the port was in use
            scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
        )
    with _quiet_distributed(), cluster, Client(cluster) as client:
        try:
            yield client
        except (Interrupted, KeyboardInterrupt):
            # the cluster closing under a stopped run: its warnings (here and in the workers, whose
            # cancelled tasks complain) are not the user's business
            _quiet_dask()
            with contextlib.suppress(Exception):
                client.run(_quiet_dask)
            raise


@contextlib.contextmanager
def _sigint_ignored() -> Iterator[None]:
    """SIGINT ignored within the block (in the main thread; elsewhere the block runs unchanged).

    Processes started in the block inherit the ignored disposition (it survives ``exec``). A Ctrl-C
    in the block (the second or two a local cluster takes to start) is lost.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _quiet_dask() -> None:
    """Silence the ``distributed`` loggers of this process (for the rest of it)."""
    for name in ["distributed", *[n for n in logging.root.manager.loggerDict if n.startswith("distributed.")]]:
        logging.getLogger(name).setLevel(logging.CRITICAL + 1)
