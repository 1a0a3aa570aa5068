"""Draw a page's figures in parallel worker processes, each figure whole in one process, in page order.

A figure costs a fraction of a second of matplotlib's layout, text rendering and rasterization, all in
Python or holding the GIL, so threads would not overlap; the report's 18 figures are shared among forked
processes (one per CPU this process may use), which inherit the data and the imported matplotlib, so
nothing is pickled but a figure's index and its path. Where fork is not offered, with one CPU or one
figure, or with :data:`PROCESSES_ENV` set to 1, they are drawn here one after another. The PNGs are the same bytes either way (tests/reporting/test_drawing.py).
Each worker freezes the heap it inherited in the garbage collector's permanent generation, so that its
collections traverse only its figures' objects; this process's collector is left as it was.

The workers ignore SIGINT: an interrupt (Ctrl-C reaches the whole process group) is this process's to
handle. On an interrupt or a figure's error the figures not yet started are dropped, the running ones
finish, and the workers are joined before the error goes on, so that nothing is written after the
caller's outputs are cleaned up and no process is left behind.
"""

from __future__ import annotations

import gc
import multiprocessing
import os
import signal
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

from kalcal.cpus import usable_cpus
from kalcal.errors import ConfigError

__all__ = ["PROCESSES_ENV", "draw_all", "drawing_workers"]

#: environment variable capping the drawing processes (a whole number >= 1; 1 draws in this process)
PROCESSES_ENV = "KALCAL_FIGURE_PROCESSES"

#: the figures being drawn: set before the workers fork, so they inherit them
_DRAWS: Sequence[Callable[[Path], Path]] = ()


def drawing_workers(figures: int) -> int:
    """Processes to draw ``figures`` figures with: one per usable CPU, at most one per figure and at most
    :data:`PROCESSES_ENV` where it is set; 1 when fork is not offered (the workers must inherit the
    figures' data). A :data:`PROCESSES_ENV` that is not a whole number >= 1 in ASCII digits is a
    ConfigError (``"²"``, ``"٣"``, ``"+2"`` included: str.isdigit and int accept some of them)."""
    cap = os.environ.get(PROCESSES_ENV, "").strip()
    if cap and not (cap.isascii() and cap.isdecimal() and int(cap) >= 1):
        raise ConfigError(f"{PROCESSES_ENV}: expected a whole number >= 1, got {cap!r}")
    if "fork" not in multiprocessing.get_all_start_methods():
        return 1
    limit = usable_cpus()
    return max(1, min(limit, int(cap) if cap else limit, figures))


def _quiet_worker(parent: int) -> None:
    from kalcal.reporting.figure_process import die_with_parent

    # what the worker inherited (matplotlib, the figures' data) is never garbage: frozen, the collector
    # traverses only the figures' own objects (docs/verification.md: 0.34-0.44 s of a page's 2.6 s, 0.14-0.17 s)
    gc.freeze()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with_parent()  # on Linux: gone with the process that drew the page, should it be killed
    if os.getppid() != parent:  # it was, before the kernel could be told
        os._exit(1)


def _draw(index: int, path: Path) -> Path:
    return _DRAWS[index](path)


def draw_all(
    draws: Sequence[Callable[[Path], Path]],
    paths: Sequence[Path],
    *,
    workers: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> list[Path]:
    """Run ``draws[i](paths[i])`` for every i, in ``workers`` processes (default :func:`drawing_workers`).

    ``progress(done, total)`` is called here, in this process, as each figure is written (in the order
    they finish). Returns the written paths, in the order of ``draws``. An error in
    a figure is raised here, as it would be when drawn in this process.
    """
    global _DRAWS
    total = len(draws)
    workers = drawing_workers(total) if workers is None else max(1, min(workers, total))
    if workers == 1:
        written = []
        for done, (draw, path) in enumerate(zip(draws, paths, strict=True), start=1):
            written.append(draw(path))
            if progress is not None:
                progress(done, total)
        return written
    _DRAWS = draws
    pool = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("fork"), initializer=_quiet_worker, initargs=(os.getpid(),))
    try:
        futures = {pool.submit(_draw, index, paths[index]): index for index in range(total)}
        written: list[Path | None] = [None] * total
        for done, future in enumerate(as_completed(futures), start=1):
            if future.exception() is not None:
                # the figures not started are dropped, the running ones finish; the error raised is that of
                # the first figure in page order that failed, as drawing them one after another would meet it
                pool.shutdown(wait=True, cancel_futures=True)
                failed = [f for f in futures if not f.cancelled() and f.exception() is not None]
                raise min(failed, key=futures.__getitem__).exception()
            written[futures[future]] = future.result()
            if progress is not None:
                progress(done, total)
    except BaseException:
        pool.shutdown(wait=True, cancel_futures=True)  # the running figures finish; the others are dropped
        raise
    finally:
        pool.shutdown(wait=True)
        _DRAWS = ()
    return written
