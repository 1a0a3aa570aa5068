"""Ctrl-C and SIGTERM as an exception, so that a job's cleanup runs before the process ends.

Python turns SIGINT into ``KeyboardInterrupt`` but lets SIGTERM end the process at once, with no
``finally`` run: a job killed that way would leave its half-written outputs behind. Inside
:func:`raise_on_signals` both signals raise :class:`Interrupted`, which unwinds the stack like any
exception (so that :mod:`kalcal.io.outputs` can remove a staged set) and carries the exit status a
shell expects, 128 + the signal number: 130 for SIGINT, 143 for SIGTERM.

:func:`deferred_signals` holds both signals back over a few statements that must not be cut in two
(the renames that put a finished set of outputs in place) and delivers them right after.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator

#: the signals a user sends to stop a run: Ctrl-C and ``kill`` (or a batch system's stop)
SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Interrupted(BaseException):
    """The run was stopped by a signal.

    A ``BaseException`` like ``KeyboardInterrupt``, so that ``except Exception`` does not swallow it.

    Attributes
    ----------
    signum : int
        The signal (2 for SIGINT, 15 for SIGTERM).
    exit_status : int
        128 + ``signum``, the status a shell reports for a process ended by that signal.
    """

    def __init__(self, signum: int) -> None:
        self.signum = int(signum)
        self.exit_status = 128 + self.signum
        super().__init__(f"interrupted by {signal.Signals(self.signum).name}")


def _in_main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def _raise(signum: int, frame) -> None:
    raise Interrupted(signum)


@contextlib.contextmanager
def raise_on_signals() -> Iterator[None]:
    """Within the block, SIGINT and SIGTERM raise :class:`Interrupted` in the main thread.

    The previous handlers come back on leaving. A signal the process was started ignoring (SIGINT in a
    shell's background job, ``nohup``) stays ignored. Outside the main thread (where Python cannot set
    handlers) the block runs unchanged.
    """
    if not _in_main_thread():
        yield
        return
    previous = {
        signum: signal.signal(signum, _raise) for signum in SIGNALS if signal.getsignal(signum) is not signal.SIG_IGN
    }
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


@contextlib.contextmanager
def deferred_signals() -> Iterator[None]:
    """Hold SIGINT and SIGTERM back within the block; deliver the first one that came right after it.

    The block should be short (a few renames): a signal waits for it to end. Outside the main thread
    the block runs unchanged.
    """
    if not _in_main_thread():
        yield
        return
    received: list[int] = []
    previous = {signum: signal.signal(signum, lambda s, f: received.append(s)) for signum in SIGNALS}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        if received:
            # the restored handler (raise Interrupted, KeyboardInterrupt, or the default: end the process)
            signal.raise_signal(received[0])
