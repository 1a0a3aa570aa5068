"""Draw a page's figures in parallel worker processes, each figure whole in one process, in page order.

A figure costs a fraction of a second to a second of matplotlib's layout and rasterization, all in
Python, so threads would not overlap; the report's 17 figures are shared among forked processes (one
per CPU this process may use), which inherit the data and the imported matplotlib, so nothing is pickled
but a figure's index and its path. Where fork is not offered, or with one CPU or one figure, they are
drawn here one after another. The PNGs are the same bytes either way (tests/reporting/test_drawing.py).
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

__all__ = ["draw_all", "drawing_workers"]

#: the figures being drawn: set before the workers fork, so they inherit them
_DRAWS: Sequence[Callable[[Path], Path]] = ()


def drawing_workers(figures: int) -> int:
    """Processes to draw ``figures`` figures with: one per usable CPU, at most one per figure; 1 when
    fork is not offered (the workers must inherit the figures' data)."""
    if "fork" not in multiprocessing.get_all_start_methods():
        return 1
    return max(1, min(len(os.sched_getaffinity(0)), figures))


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
    they finish). Returns the written paths, in the order of ``draws``. An error in a figure is raised
    here, as it would be when drawn in this process.
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
    try:
        with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("fork")) as pool:
            futures = {pool.submit(_draw, index, path): index for index, path in enumerate(paths)}
            written: list[Path | None] = [None] * total
            for done, future in enumerate(as_completed(futures), start=1):
                written[futures[future]] = future.result()
                if progress is not None:
                    progress(done, total)
    finally:
        _DRAWS = ()
    return written
