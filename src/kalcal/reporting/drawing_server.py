"""The figure process of a job with a report: forked at its start, it imports the plotting modules and draws.

A job that draws its report (``kalcal verify``, :func:`kalcal.verify` with ``report``) spends its first
seconds importing numpy, numba, xarray and scipy on one core, then the Monte Carlo, and only then needs
matplotlib and the plotting modules (about a second more of imports). :func:`serving` forks one process
before those imports, which imports the plotting modules (:data:`PRELOAD`) while this process imports and
computes, then waits on a pipe. At report time :func:`call` sends it the function that draws the page
and its arguments (pickled: the statistics, the realization shown, the steady state, the summary); it
runs it there (its figures are drawn by :func:`kalcal.reporting.drawing.draw_all`'s workers, forked from
it and so inheriting matplotlib), forwards each figure's progress and sends back the result or the error,
which :func:`call` raises here as it would have been raised drawing here (the same type and message).
This process then never imports matplotlib.

The figure process is forked only where fork is offered, with more than one usable CPU and without
:data:`~kalcal.reporting.drawing.PROCESSES_ENV` set to 1; otherwise, or once it has served one call, or
if it has died, :func:`call` draws here, as a job without one does.

It ignores SIGINT (an interrupt is this process's to handle) and serves one call. When the job ends,
fails or is interrupted, :func:`serving` stops it and waits for it: an idle one is killed; one drawing is
sent SIGTERM, on which its running figures finish, the others are dropped and its workers are joined,
so that nothing is written after the job's outputs are cleaned up and no process is left behind. If
this process dies, the figure process sees its pipe close and exits.
"""

from __future__ import annotations

import contextlib
import importlib
import multiprocessing
import os
import pickle
import signal
from collections.abc import Callable, Iterator
from typing import Any

from kalcal.reporting.drawing import PROCESSES_ENV

__all__ = ["PRELOAD", "FigureProcess", "call", "current", "serving"]

#: what the figure process imports while the job computes: everything the page is drawn with
PRELOAD = ("kalcal.reporting.figures", "kalcal.reporting.html", "kalcal.jobs.report")
#: seconds to wait for a stopped figure process to finish its running figures before it is killed
STOP_TIMEOUT = 60.0

_CURRENT: FigureProcess | None = None


class _Stop(BaseException):
    """Raised in the figure process by SIGTERM: this process asked it to stop."""


class ServerGone(RuntimeError):
    """The figure process died before it answered (the call is then made here)."""


def wanted() -> bool:
    """Whether a figure process may be forked: fork is offered, more than one CPU is usable and
    :data:`~kalcal.reporting.drawing.PROCESSES_ENV` does not ask for drawing in one process."""
    cap = os.environ.get(PROCESSES_ENV, "").strip()
    if cap.isascii() and cap.isdigit() and int(cap) == 1:
        return False
    if "fork" not in multiprocessing.get_all_start_methods():
        return False
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return cpus > 1


def _on_term(signum, frame) -> None:
    raise _Stop


def _serve(connection, other_end, preload: tuple[str, ...]) -> None:
    """The figure process: import ``preload``, answer one call, exit (at once on EOF or SIGTERM)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _on_term)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})  # blocked across the fork
    other_end.close()  # this process's copy of the parent's end: EOF must reach us when the parent dies
    try:
        for name in preload:
            with contextlib.suppress(Exception):  # an import error is raised by the call that needs it
                importlib.import_module(name)
        try:
            function, args, kwargs = connection.recv()
        except EOFError:
            return
        try:
            result = ("done", function(*args, progress=lambda done, total: connection.send(("progress", done, total)), **kwargs))
        except Exception as exc:  # sent back as it is, or as its type's name and message
            result = ("error", _portable(exc))
        connection.send(result)
    except (_Stop, EOFError, BrokenPipeError):
        pass
    finally:
        connection.close()


def _portable(exc: Exception) -> Exception:
    """``exc``, or an error of its kind with its message where it does not survive pickling."""
    try:
        back = pickle.loads(pickle.dumps(exc))
        if type(back) is type(exc) and str(back) == str(exc):
            return exc
    except Exception:
        pass
    from kalcal.errors import KalcalError

    kind = KalcalError if isinstance(exc, KalcalError) else RuntimeError
    return kind(str(exc) if kind is KalcalError else f"{type(exc).__name__}: {exc}")


class FigureProcess:
    """One forked figure process and this process's end of its pipe."""

    def __init__(self, process, connection) -> None:
        self.process = process
        self.connection = connection
        self.used = False  #: it has been sent its one call
        self.busy = False  #: a call is in flight

    @property
    def pid(self) -> int:
        """The figure process's id."""
        return self.process.pid

    @classmethod
    def start(cls, preload: tuple[str, ...] = PRELOAD) -> FigureProcess:
        """Fork a figure process that imports ``preload`` and waits for its call (the caller blocks
        SIGINT and SIGTERM across the fork: the child unblocks them once it has set its handlers)."""
        context = multiprocessing.get_context("fork")
        ours, theirs = context.Pipe()
        process = context.Process(target=_serve, args=(theirs, ours, preload), name="kalcal-figures")
        try:
            process.start()
        finally:
            theirs.close()
        return cls(process, ours)

    def call(self, function: Callable[..., Any], *args, progress: Callable[[int, int], None] | None = None, **kwargs) -> Any:
        """``function(*args, progress=..., **kwargs)`` run in the figure process; its ``progress(done,
        total)`` calls are made here. Its error is raised here; :class:`ServerGone` if it died first."""
        self.used = self.busy = True
        try:
            try:
                self.connection.send((function, args, kwargs))
            except (BrokenPipeError, ConnectionResetError, EOFError) as exc:
                raise ServerGone(f"the figure process has exited ({exc})") from None
            while True:
                try:
                    message = self.connection.recv()
                except (EOFError, ConnectionResetError):
                    raise ServerGone("the figure process exited before it answered") from None
                if message[0] == "progress":
                    if progress is not None:
                        progress(*message[1:])
                    continue
                self.busy = False
                if message[0] == "error":
                    raise message[1]
                return message[1]
        except BaseException:
            self.close()  # the running figures finish, then the process is gone: nothing written after this
            raise
        finally:
            self.busy = False

    def close(self) -> None:
        """Stop the figure process and wait for it (an idle one is killed, a drawing one sent SIGTERM)."""
        process = self.process
        self.connection.close()
        if process.pid is None:
            return
        if process.is_alive():
            if self.busy:
                process.terminate()  # SIGTERM: its figures running finish, its workers are joined
                process.join(STOP_TIMEOUT)
            if process.is_alive():
                process.kill()
        process.join()


def current() -> FigureProcess | None:
    """The figure process that serves this process's job, if one is waiting for its call."""
    return _CURRENT if _CURRENT is not None and not _CURRENT.used else None


@contextlib.contextmanager
def serving(report: bool) -> Iterator[FigureProcess | None]:
    """Within the block, a job's report is drawn in a figure process forked now (with ``report``, where
    :func:`wanted`); one already serving this process (forked by an enclosing block) is kept. It is
    stopped and waited for when the block ends, however it ends."""
    global _CURRENT
    if not report or _CURRENT is not None or not wanted():
        yield current()
        return
    server = None
    # no SIGINT nor SIGTERM may reach the child before it sets its handlers; one pending here is raised
    # once they are unblocked, with the server already in hand to stop
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
    try:
        try:
            server = _CURRENT = FigureProcess.start()
        except OSError:  # no process to fork (limits, memory): the figures are drawn here
            pass
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        yield server
    finally:
        _CURRENT = None
        if server is not None:
            server.close()


def call(function: Callable[..., Any], *args, progress: Callable[[int, int], None] | None = None, **kwargs) -> Any:
    """``function(*args, progress=progress, **kwargs)``: in the figure process serving this job if there
    is one (:func:`serving`), else here (also when it has died before answering)."""
    server = current()
    if server is not None:
        try:
            return server.call(function, *args, progress=progress, **kwargs)
        except ServerGone:
            pass  # drawn here instead, from the first figure
    return function(*args, progress=progress, **kwargs)
