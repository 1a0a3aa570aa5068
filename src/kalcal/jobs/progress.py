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

#: The stages of ``kalcal verify`` in the order they run, and their units.
STAGES = {
    "monte carlo": "realizations",
    "long run": "realizations",
    "statistics": "files",
    "figures": "figures",
    "report": "pages",
}


def stage(progress: JobProgress | None, name: str) -> Callable[[int, int], None] | None:
    """The engine's ``(done, total)`` callback for one stage of ``progress`` (None when it is None)."""
    if progress is None:
        return None
    if name not in STAGES:
        raise ValueError(f"unknown progress stage {name!r} (have {', '.join(STAGES)})")

    def update(done: int, total: int) -> None:
        progress(name, done, total)

    return update
