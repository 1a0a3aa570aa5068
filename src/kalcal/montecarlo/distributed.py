"""Dask as the scale-out engine: a local cluster of processes or an existing scheduler.

The engine submits blocks of realizations as Dask tasks (:func:`kalcal.montecarlo.engine.block_task`)
and folds their sums in block order, so the numbers do not depend on the cluster. A worker that dies
mid-task has its task rerun by the scheduler on another worker. The local cluster's worker processes
ignore SIGINT: a Ctrl-C stops the run (one line, ``kalcal: interrupted``) and this process closes them.
Dask (``dask[distributed]``) is a
default dependency of kalcal.

distributed logs its own events (a worker lost, the nanny restarting it, keys gathered again) as several
lines on stderr. Given a ``notes`` callback, :func:`dask_client` routes them while the client lives: each
event is one call of ``notes(text)`` (the CLI prints ``kalcal: note: TEXT``), and the log lines of the
local cluster's worker processes are forwarded to this process and routed the same way. A worker the nanny
starts in a lost one's place ignores SIGINT once it is set up (a Ctrl-C had printed its traceback); one in
the second or two while that worker imports still reaches it. Once a run is stopped, no more notes.
"""

from __future__ import annotations

import contextlib
import logging
import re
import signal
import threading
import warnings
from collections.abc import Callable, Iterator

from kalcal.errors import ConfigError
from kalcal.interrupts import Interrupted


@contextlib.contextmanager
def _quiet_distributed() -> Iterator[None]:
    """distributed's own UserWarnings (the dashboard's port 8787 taken by another cluster, so it moves to
    a free one) say nothing about the run: kept off the user's stderr while the cluster lives."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", category=UserWarning, module=r"distributed(\.|$)")
        yield


#: records of distributed of one kind (:func:`event_kind`) within this many seconds of the first record of
#: their event belong to that event: a worker lost is logged by the scheduler, the client and the nanny
#: within a tenth of a second on an idle machine, and seconds apart on a loaded one (the nanny's restart
#: waits for the process to be reaped). The window is counted from the event's first record, so a steady
#: stream of records (a memory warning every second, say) is one note per window, not one note in all.
EVENT_WINDOW_S = 5.0

#: the note of a lost worker, whichever of its records arrives first
WORKER_LOST = "a Dask worker was lost; its tasks run again (the numbers do not change)"

#: the records distributed (2026.8) logs when a worker dies mid-run, by message. Which of them arrives
#: first varies from run to run: the scheduler's ``Couldn't gather keys: {key: 'memory'}`` (the key was in the
#: dead worker's memory, not an out-of-memory error) came first in some runs, the nanny's ``Restarting
#: worker`` in others, so every one of them names the same event.
_WORKER_LOST_RECORDS = re.compile(
    r"Removing worker .* caused the cluster to lose"
    r"|Restarting worker"
    r"|Couldn't gather (\d+ )?keys"
    r"|Worker process \d+ was killed by (unknown )?signal"
)


def event_kind(record: logging.LogRecord) -> str:
    """The kind of event a record of distributed belongs to: ``"worker-lost"`` for the records of a
    worker dying (:data:`_WORKER_LOST_RECORDS`), whatever their logger and level; any other record is of
    the kind ``"logger:level"`` (``"distributed.worker.memory:WARNING"``), so that an error is never
    taken for the tail of another logger's or another level's event (a memory warning followed by an
    error within the window gives two notes)."""
    if _WORKER_LOST_RECORDS.search(record.getMessage()):
        return "worker-lost"
    return f"{record.name}:{record.levelname}"


def event_text(record: logging.LogRecord) -> str:
    """The note of an event whose first record is ``record``: :data:`WORKER_LOST` for a worker's death,
    any other as ``Dask (logger, level): first line of the message``."""
    if event_kind(record) == "worker-lost":
        return WORKER_LOST
    message = record.getMessage().splitlines()[0] if record.getMessage() else ""
    return f"Dask ({record.name}, {record.levelname.lower()}): {message[:300]}"


class NoteHandler(logging.Handler):
    """A logging handler that turns each event of distributed's log into one ``notes(text)`` call
    (:func:`event_text`). An event is the records of one kind (:func:`event_kind`: a worker lost, or one
    logger at one level) from its first record to :data:`EVENT_WINDOW_S` after it; a record of another
    kind inside that window is an event of its own (a worker lost during a stream of memory warnings is
    still noted, and so is an error after a warning)."""

    def __init__(self, notes: Callable[[str], None], window: float = EVENT_WINDOW_S):
        super().__init__(level=logging.WARNING)
        self.notes = notes
        self.window = window
        self.started: dict[str, float] = {}  # kind -> time of the first record of its current event (s)
        self.muted = False  # set when the run is stopped: the cluster's closing records are not news

    def emit(self, record: logging.LogRecord) -> None:
        if self.muted:
            return
        kind = event_kind(record)
        if record.created - self.started.get(kind, float("-inf")) <= self.window:
            return
        self.started[kind] = record.created
        try:
            self.notes(event_text(record))
        except Exception:
            self.handleError(record)


def _distributed_loggers() -> list[logging.Logger]:
    """The loggers of distributed that have handlers of their own (dask's logging configuration gives
    ``distributed``, ``distributed.client`` and ``distributed.gc`` each a stderr handler)."""
    names = ["distributed", *sorted(n for n in logging.root.manager.loggerDict if n.startswith("distributed."))]
    return [logger for logger in map(logging.getLogger, names) if logger.handlers]


@contextlib.contextmanager
def notes_for_logs(notes: Callable[[str], None] | None) -> Iterator[None]:
    """While the block runs, distributed's log in this process goes to ``notes`` (one call per event)
    instead of its own stderr handlers; nothing changes for None."""
    if notes is None:
        yield
        return
    handler = NoteHandler(notes)
    saved = [(logger, list(logger.handlers), logger.propagate) for logger in _distributed_loggers()]
    if not any(logger.name == "distributed" for logger, _, _ in saved):
        saved.append((logging.getLogger("distributed"), [], logging.getLogger("distributed").propagate))
    for logger, handlers, _ in saved:
        for old in handlers:
            logger.removeHandler(old)
        logger.addHandler(handler)
        logger.propagate = False
    try:
        yield
    finally:
        for logger, handlers, propagate in saved:
            logger.removeHandler(handler)
            for old in handlers:
                logger.addHandler(old)
            logger.propagate = propagate


def _worker_logs_forwarded_only(client) -> None:
    """The local cluster's workers (and those the nannies restart) send their distributed log records to
    this process (:meth:`Client.forward_logging`) instead of writing them to the terminal themselves."""
    from distributed.diagnostics.plugin import WorkerPlugin

    class SilentStderr(WorkerPlugin):
        def setup(self, worker):
            # a worker the nanny starts again (after one was lost) is spawned with SIGINT at its default,
            # and a Ctrl-C then printed its KeyboardInterrupt traceback: ignored here, in the worker's main
            # thread, as for the first workers (:func:`_sigint_ignored`)
            if threading.current_thread() is threading.main_thread():
                signal.signal(signal.SIGINT, signal.SIG_IGN)
            names = ["distributed", *(n for n in logging.root.manager.loggerDict if n.startswith("distributed."))]
            for logger in map(logging.getLogger, names):
                for handler in list(logger.handlers):
                    if type(handler) is logging.StreamHandler:  # the terminal's, not the forwarding handler
                        logger.removeHandler(handler)

    client.register_plugin(SilentStderr(), name="kalcal-silent-stderr")
    client.forward_logging("distributed", level=logging.WARNING)


@contextlib.contextmanager
def dask_client(
    workers: int | None = None, scheduler: str | None = None, notes: Callable[[str], None] | None = None
) -> Iterator[object | None]:
    """A ``dask.distributed.Client``: on ``scheduler`` if given, else on a new local cluster of ``workers``
    single-threaded processes; None when neither is asked for (the engine then uses local threads).
    ``notes(text)``, if given, hears each event of distributed's own log instead of stderr (module
    docstring)."""
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
        with notes_for_logs(notes), client:
            yield client
        return
    # the worker processes start with SIGINT ignored: Ctrl-C (sent to the whole process group) stops this
    # process, which then closes the cluster, instead of every worker printing its own traceback
    with notes_for_logs(notes):
        yield from _local_cluster(workers, notes)


def _local_cluster(workers: int, notes) -> Iterator[object]:
    """:func:`dask_client`'s local cluster, its client yielded."""
    from distributed import Client, LocalCluster

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
        if notes is not None:
            _worker_logs_forwarded_only(client)
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
    """Silence the ``distributed`` loggers of this process (for the rest of it), and the notes of its log:
    records forwarded from the workers are handled whatever the logger's level."""
    for name in ["distributed", *[n for n in logging.root.manager.loggerDict if n.startswith("distributed.")]]:
        logger = logging.getLogger(name)
        logger.setLevel(logging.CRITICAL + 1)
        for handler in logger.handlers:
            if isinstance(handler, NoteHandler):
                handler.muted = True
