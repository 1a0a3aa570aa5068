"""``kalcal report``: redraw the figures and report.html of a saved verification run, through :func:`kalcal.report`."""

from pathlib import Path
from typing import Annotated

import typer

from kalcal.cli import _common
from kalcal.cli._common import user_errors


def report(
    directory: Annotated[Path, typer.Argument(help="A directory written by kalcal verify.")],
    realization: Annotated[int, typer.Option("--realization", help="Realization shown in the single-run figures.")] = 0,
) -> None:
    """Redraw the figures and report.html of a verification run from its summary.json and stats.nc."""
    from kalcal.api.report import report as redraw

    with user_errors():
        bar, update = _common._progress_bar(str(directory))
        with bar:
            paths = redraw(directory, realization, progress=update)
    _common.print_wrote(Path(directory), [paths["report"], paths["figures"]])
