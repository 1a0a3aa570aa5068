"""Progress for an API call: a callable as given, a rich bar on stderr for ``progress=True``, or nothing."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator


@contextlib.contextmanager
def progress_callback(progress, title: str) -> Iterator:
    """Yield the job's ``progress(stage, done, total)`` callback (None for silence) for the block."""
    if callable(progress):
        yield progress
        return
    if not progress:
        yield None
        return
    from rich.console import Console

    bar, update = progress_bar(title, Console(stderr=True))
    with bar:
        yield update


def progress_bar(title: str, console):
    """A rich progress bar on ``console``: returns (context manager, callback ``(stage, done, total)``).

    The bar shows the stage, its count of units and its time (:mod:`kalcal.montecarlo.progress`).
    """
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    from kalcal.montecarlo.progress import STAGES

    bar = Progress(
        TextColumn("{task.description}", markup=False),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[unit]}", markup=False),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=console,
        transient=True,
    )
    task = bar.add_task(title, total=None, unit="")

    def update(stage: str, done: int, total: int) -> None:
        bar.update(task, description=f"{title}: {stage}", completed=done, total=total, unit=STAGES.get(stage, ""))

    return bar, update
