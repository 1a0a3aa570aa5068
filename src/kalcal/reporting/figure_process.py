"""Figures drawn in a process started with the job, which loads the plotting code while the job computes.

Loading matplotlib and the figure modules costs about half a second, in one thread, and a job that draws
(``kalcal verify`` with its report, ``kalcal report``, ``calibrate accel-gps``, ``fit``, ``noise``,
``analyze``, ``sweep``) would otherwise pay it after its computation, on its critical path.
:func:`figure_process` starts a fresh interpreter beside the job instead (a subprocess, not a fork: the job
may already run threads), which loads the plotting code on another core while the job loads its own
libraries and computes; the job's figure calls (:func:`call`, :func:`submit`) then run there, and the
process that draws never needs matplotlib at all. A figure is the same bytes in either process
(tests/reporting/test_figure_process.py); inside it, a page's figures are still shared among forked workers
(:mod:`kalcal.reporting.drawing`).

It starts only where it can help and changes nothing else: on POSIX, with at least two usable CPUs,
when this process has not loaded matplotlib yet (a notebook that has keeps drawing here, with its own
rcParams), once per process (a script that calls the API in a loop pays matplotlib's import once, in its
second call, rather than a figure process's in every call), and unless
:data:`~kalcal.reporting.drawing.PROCESSES_ENV` is 1 (draw in this process). Without it, :func:`call`
imports the function and runs it here.

The process runs in a process group of its own and ignores SIGINT (an interrupt is the job's to handle:
the terminal's Ctrl-C never reaches it) and SIGTTOU (as a background group it may still write to the
terminal with ``stty tostop``), in the job's session (where Linux's scheduler autogroups are enabled,
the job's autogroup, where its nice-19 loading yields to the job's threads) and, on Linux, is killed when
the job's process dies (``PR_SET_PDEATHSIG``), as are its drawing workers. When the job stops (an error, Ctrl-C,
SIGTERM) it asks the process to stop: the figures not yet started are dropped, the running ones finish,
and the process is waited for before the error goes on, so that nothing is written after the job's
outputs are cleaned up. Should the process die (killed from outside), the figure is drawn here instead.
"""

from __future__ import annotations

import contextlib
import contextvars
import importlib
import os
import pickle
import signal
import subprocess
import sys
import threading
from collections.abc import Callable, Iterator
from multiprocessing.connection import Connection, Pipe
from multiprocessing.reduction import ForkingPickler
from typing import Any

__all__ = ["PendingFigure", "call", "elsewhere", "figure_process", "submit"]  # the names it runs: figure_names.py

#: whether this process has drawn through a figure process it started where one helps (once: the docstring)
_STARTED = False

#: the figure process of the job running in this context, None where figures are drawn here
_CURRENT: contextvars.ContextVar[FigureProcess | None] = contextvars.ContextVar("kalcal_figure_process", default=None)

#: seconds between checks that the process is alive while waiting for its answer
_POLL_S = 0.1

# the child's first lines: its sys.path comes from the job, so it imports the job's kalcal
_BOOTSTRAP = (
    # a background process group of the job's session: with the terminal's tostop set, its first write to
    # the terminal (stderr: a warning, matplotlib's font-cache message) would stop it, and the job wait on it
    "import signal\n"
    "signal.signal(signal.SIGTTOU, signal.SIG_IGN)\n"
    "import sys\n"
    "del sys.path[0]\n"  # -c puts the current folder first: a stray socket.py there is not imported
    "from multiprocessing.connection import Connection\n"
    "connection = Connection(int(sys.argv[1]))\n"
    "sys.path[:] = connection.recv()\n"
    "from kalcal.reporting.figure_process import serve\n"
    "serve(connection)\n"
)


class _Stop(Exception):
    """The job asked the figure process to stop (raised in it, inside the drawing's progress callback)."""


class _NotSent(Exception):
    """The call's arguments do not pickle: it is drawn in the job's process."""


class FigureProcessDied(RuntimeError):
    """The figure process ended without answering (killed from outside)."""


def die_with_parent() -> None:
    """On Linux, have the kernel kill this process when its parent dies (``PR_SET_PDEATHSIG``); elsewhere
    nothing (the figure process then ends when its connection to the job closes)."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes

    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # 1: PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


class FigureProcess:
    """A Python process that has loaded ``modules`` and runs the functions it is sent, one at a time."""

    def __init__(self, modules: tuple[str, ...]):
        parent, child = Pipe()
        try:
            self._process = subprocess.Popen(
                [sys.executable, "-c", _BOOTSTRAP, str(child.fileno())],
                pass_fds=(child.fileno(),), stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                # a process group of its own: the terminal's Ctrl-C (sent to the foreground group) is the
                # job's, from the child's first instant; the job's session, so that on Linux it shares the
                # job's scheduler autogroup, where its nice-19 loading yields to the job (a session of its
                # own would be an autogroup of its own, given an equal share of the CPUs against the job)
                process_group=0,
            )
        finally:
            child.close()
        self._connection = parent
        parent.send(list(sys.path))
        parent.send((os.getpid(), modules))
        self.busy = False  # a call sent and not answered yet
        self.used = False  # a call sent at all
        self.ended = False  # stopped or dead: calls are then drawn in the job's process

    def _died(self) -> FigureProcessDied:
        """It has ended without answering: marked so (later calls are drawn here), and the error to raise."""
        self._process.wait()
        self.busy, self.ended = False, True
        return FigureProcessDied(f"the figure process ended (status {self._process.returncode})")

    def request(self, name: str, args: tuple, kwargs: dict[str, Any]) -> None:
        """Send the call of ``name`` (``"module:function"``) with its arguments; :meth:`answer` waits for it.

        Busy from before the send: an interrupt during it leaves a call that :meth:`stop` waits for.
        Arguments that do not pickle leave the call to this process (FigureProcessDied is not raised
        then: the process stays for later calls)."""
        try:
            message = ForkingPickler.dumps(("call", name, args, kwargs))
        except Exception:
            raise _NotSent from None
        self.busy = self.used = True
        try:
            self._connection.send_bytes(message)
        except OSError:
            raise self._died() from None

    def answer(self, progress: Callable[[int, int], None] | None) -> Any:
        """Wait for the answer to the call sent, passing its progress on; its error is raised here.

        Interrupted (or failing) while waiting, it stops the process first (:meth:`stop`). Raises
        FigureProcessDied when the process ended without answering.
        """
        try:
            while True:
                while not self._connection.poll(_POLL_S):
                    if self._process.poll() is not None:
                        raise self._died()
                try:
                    kind, *payload = self._connection.recv()
                except (EOFError, OSError):
                    raise self._died() from None
                if kind == "progress":
                    if progress is not None:
                        progress(*payload)
                    continue
                self.busy = False
                if kind == "error":
                    raise payload[0]
                return payload[0]
        except BaseException:
            if self.busy:  # not after FigureProcessDied: it has ended
                self.stop()
            raise

    def stop(self) -> None:
        """End the process and wait for it. Idle, it is killed (it writes nothing between calls, and may
        still be loading); with a call running, it is asked to stop: the figures not yet started are
        dropped and the running ones finish, so that nothing is written once this returns."""
        if self.ended:
            return
        self.ended = True
        try:
            if self.busy:
                self._connection.send(("stop",))
            else:
                self._process.kill()
            self._connection.close()
        except OSError:
            pass  # it has gone already
        finally:
            self.busy = False
            try:
                self._process.wait()
            except BaseException:
                self._process.kill()  # a second interrupt while waiting (or sending): it goes now
                self._process.wait()
                raise


class PendingFigure:
    """A figure call started by :func:`submit`: :meth:`result` waits for it, :meth:`cancel` abandons it; a
    ``with`` block waits for it at its end, or stops it before the block's error goes on."""

    def __init__(self, process: FigureProcess | None, name: str, args: tuple, kwargs: dict[str, Any], progress):
        self._process, self._name, self._args, self._kwargs, self._progress = process, name, args, kwargs, progress
        self._done = process is None
        if process is not None:
            try:
                process.request(name, args, {**kwargs, **({"progress": True} if progress is not None else {})})
            except (FigureProcessDied, _NotSent):
                self._done = True
            except BaseException:  # interrupted once busy: the call is stopped before the error goes on
                process.stop()
                raise
        if self._done:
            self._value = _run_here(name, args, kwargs, progress)

    def result(self) -> Any:
        """The call's result (its error raised here); drawn here instead if the figure process died."""
        if not self._done:
            self._done = True
            try:
                self._value = self._process.answer(self._progress)
            except FigureProcessDied:
                self._value = _run_here(self._name, self._args, self._kwargs, self._progress)
        return self._value

    def cancel(self) -> None:
        """Abandon the call: the figure process stops (its running figures finish) before this returns."""
        if not self._done:
            self._done = True
            self._process.stop()

    def __enter__(self) -> PendingFigure:
        return self

    def __exit__(self, failed, *_) -> None:
        self.cancel() if failed else self.result()  # noqa: B018 (one of the two, for its effect)


def _helps() -> bool:
    """Whether a figure process would save this job time (see the module's docstring)."""
    from kalcal.reporting.drawing import PROCESSES_ENV, usable_cpus

    return (os.name == "posix" and not _STARTED and "matplotlib" not in sys.modules and usable_cpus() >= 2
            and os.environ.get(PROCESSES_ENV, "").strip() != "1")  # fmt: skip


@contextlib.contextmanager
def figure_process(*functions: str, start: bool | None = None) -> Iterator[FigureProcess | None]:
    """For the ``with`` block, a figure process that loads the modules of ``functions`` (``"module:function"``:
    the figure code the job will call) while the block runs; :func:`call` and :func:`submit` inside the
    block use it.

    ``start`` None starts it where it helps (see the module's docstring), True always, False never.
    Yields the process, or None where figures are drawn in this process.
    """
    global _STARTED
    if not (_helps() if start is None else start):
        token = _CURRENT.set(None)
        try:
            yield None
        finally:
            _CURRENT.reset(token)
        return
    process = FigureProcess(tuple(dict.fromkeys(name.partition(":")[0] for name in functions)))
    token = _CURRENT.set(process)
    try:
        yield process
    finally:
        _CURRENT.reset(token)
        process.stop()
        _STARTED = _STARTED or (start is None and process.used)  # a job that drew nothing leaves it for the next


def _function(name: str) -> Callable[..., Any]:
    module, _, function = name.partition(":")
    return getattr(importlib.import_module(module), function)


def _run_here(name: str, args: tuple, kwargs: dict[str, Any], progress) -> Any:
    return _function(name)(*args, **kwargs, **({"progress": progress} if progress is not None else {}))


def submit(name: str, *args: Any, progress: Callable[[int, int], None] | None = None, **kwargs: Any) -> PendingFigure:
    """Start ``name(*args, **kwargs)`` (``"module:function"``) in the job's figure process and return it
    pending (:class:`PendingFigure`); ``progress(done, total)``, the function's own keyword, is called here
    as the figure process reports it.

    Without a figure process (or with one busy or ended) the call runs here, now.
    """
    return PendingFigure(_CURRENT.get() if elsewhere() else None, name, args, kwargs, progress)


def elsewhere() -> bool:
    """Whether a figure call now would run in the job's figure process (one started, not busy, not ended)."""
    process = _CURRENT.get()
    return process is not None and not process.busy and not process.ended


def call(name: str, *args: Any, progress: Callable[[int, int], None] | None = None, **kwargs: Any) -> Any:
    """``name(*args, **kwargs)`` in the job's figure process, or here without one: :func:`submit`, waited for."""
    return submit(name, *args, progress=progress, **kwargs).result()


def serve(connection: Connection) -> None:
    """The figure process's loop: load the modules, then run each call sent until told to exit."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    parent, modules = connection.recv()
    die_with_parent()
    if os.getppid() != parent:  # the job died before the kernel could be told
        return
    if not _load(modules):
        return  # the job then draws the figures itself, and meets the error there
    while True:
        try:
            message = connection.recv()
        except Exception:  # closed, or cut short by an interrupt in the job's send
            return
        if message[0] != "call":  # a stop, even one that came after its call had finished
            return
        _, name, args, kwargs = message
        if connection.poll():  # the job stopped before this call was taken (while loading, say)
            return
        if kwargs.pop("progress", None):
            kwargs["progress"] = _progress_sender(connection)
        try:
            result = ("result", _function(name)(*args, **kwargs))
        except _Stop:
            return
        except BaseException as exc:  # the job's error to raise, as it would be here
            result = ("error", _picklable(exc))
        try:
            connection.send(result)
        except (OSError, ValueError):
            return
        except Exception as exc:  # a result that does not pickle: said as an error, not a dead process
            with contextlib.suppress(OSError, ValueError):
                connection.send(("error", RuntimeError(f"{name}: its result could not be sent back ({exc})")))


def _load(modules: tuple[str, ...]) -> bool:
    """Import ``modules``; whether they all loaded. On Linux the imports run in a thread of the lowest
    priority (nice 19; a thread's own there), so that they take only what the job leaves of the CPUs
    (its Monte Carlo takes them all) and never slow it down; the figures are drawn at this process's
    own priority, in workers forked from the main thread."""
    loaded = []

    def load() -> None:
        if sys.platform.startswith("linux"):
            with contextlib.suppress(OSError):
                os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), 19)
        try:
            for module in modules:
                importlib.import_module(module)
            loaded.append(True)
        except Exception:
            pass

    worker = threading.Thread(target=load, name="kalcal-figure-imports")
    worker.start()
    worker.join()
    return bool(loaded)


def _progress_sender(connection: Connection) -> Callable[[int, int], None]:
    """A progress callback that tells the job, and stops the call when the job has asked it to."""

    def progress(done: int, total: int) -> None:
        if connection.poll():  # the job sends nothing else during a call
            raise _Stop
        connection.send(("progress", done, total))

    return progress


def _picklable(exc: BaseException) -> BaseException:
    """``exc`` itself when it survives pickling, else a RuntimeError with its type and message."""
    try:
        pickle.loads(pickle.dumps(exc))
        return exc
    except Exception:
        return RuntimeError(f"{type(exc).__name__}: {exc}")
