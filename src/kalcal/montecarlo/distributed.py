"""Dask as the scale-out engine: a local cluster of processes or an existing scheduler.

The engine submits blocks of realizations as Dask tasks (:func:`kalcal.montecarlo.engine.block_task`)
and folds their sums in block order, so the numbers do not depend on the cluster. A worker that dies
mid-task has its task rerun by the scheduler on another worker. Dask (``dask[distributed]``) is a
default dependency of kalcal.
"""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Iterator

from kalcal.errors import ConfigError


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
    with (
        _quiet_distributed(),
        LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None) as cluster,
        Client(cluster) as client,
    ):
        yield client
