"""Progress of a whole job, stage by stage, through one callback (numeric code never prints).

A job calls ``progress(stage, done, total)`` as it goes: ``stage`` names what is being done (see
:data:`STAGES`), ``done`` of ``total`` counts its units (realizations for a Monte Carlo, files for the
statistics, figures for the report). The CLI turns the calls into a progress bar; a Python caller may
pass any callable of that shape, or None for silence.
"""

from __future__ import annotations

from collections.abc import Callable

#: ``progress(stage, done, total)``
JobProgress = Callable[[str, int, int], None]

#: The stages a job may report, and their units (each named once; :data:`VERIFY_ORDER` is their order).
STAGES = {
    "monte carlo": "realizations",
    "long run": "realizations",
    "statistics": "files",
    "figures": "figures",
    "report": "pages",
}

#: The order ``kalcal verify`` (with its long run and report) goes through the stages: the statistics
#: stage comes twice, ``stats.nc`` before the long run, ``stats_long.nc`` and ``summary.json`` after it.
VERIFY_ORDER = ("monte carlo", "statistics", "long run", "statistics", "figures", "report")


def stage(progress: JobProgress | None, name: str) -> Callable[[int, int], None] | None:
    """The engine's ``(done, total)`` callback for one stage of ``progress`` (None when it is None)."""
    if progress is None:
        return None
    if name not in STAGES:
        raise ValueError(f"unknown progress stage {name!r} (have {', '.join(STAGES)})")

    def update(done: int, total: int) -> None:
        progress(name, done, total)

    return update
