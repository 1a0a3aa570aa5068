"""``kalcal.report``: redraw the figures and report.html of a saved verification folder."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from kalcal.api.progress import progress_callback


def report(
    directory: str | Path, realization: int = 0, *, progress: bool | Callable[[str, int, int], None] = False
) -> dict[str, Path]:
    """Redraw ``directory/figures/`` and ``directory/report.html`` from the ``summary.json`` and ``stats.nc``
    a verification saved there (``kalcal report DIR``), the single-run figures showing realization
    ``realization`` (0-based, below the run's N).

    Parameters
    ----------
    directory : path
        A folder written by :func:`kalcal.verify` with ``out`` (or ``kalcal verify --out``).
    realization : int
        The realization the single-run figures show.
    progress : bool or callable
        True: a progress bar on stderr; a callable: ``progress(stage, done, total)``; False: silence.

    Returns
    -------
    dict
        ``{"report": directory/report.html, "figures": directory/figures}``.

    Raises
    ------
    KalcalError
        The folder is not a finished verification run, or ``realization`` is out of range.
    """
    directory = Path(directory)
    from kalcal.reporting.render import FIGURE_DIR, render_report

    with progress_callback(progress, str(directory)) as update:
        page = render_report(directory, realization=realization, progress=update)
    return {"report": page, "figures": directory / FIGURE_DIR}
