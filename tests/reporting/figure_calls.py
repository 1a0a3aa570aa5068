"""Functions the figure-process tests send to it (importable there: it gets the tests' sys.path)."""

from __future__ import annotations

import os
import time
from pathlib import Path

from kalcal.errors import DataError
from kalcal.reporting.drawing import draw_all


def pid_and_progress(total: int, progress=None) -> int:
    """This process's pid, after ``progress(i, total)`` for i = 1..total."""
    for done in range(1, total + 1):
        if progress is not None:
            progress(done, total)
    return os.getpid()


def refuse(path: str) -> None:
    raise DataError(f"{path}: cannot be drawn")


def _slow_file(path: Path) -> Path:
    time.sleep(0.3)
    path.write_text(str(os.getpid()))
    return path


def slow_files(directory: str, total: int, progress=None) -> list[Path]:
    """``total`` files of 0.3 s each, written by two forked workers as a page's figures are."""
    paths = [Path(directory) / f"f{i}.txt" for i in range(total)]
    return draw_all([_slow_file] * total, paths, workers=2, progress=progress)


def pid_of(_anything) -> int:
    return os.getpid()


def unpicklable_result():
    return lambda: None
