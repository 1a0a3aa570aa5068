"""Writing a computed verification into its folder: ``stats.nc``, ``stats_long.nc``, the page, ``summary.json``."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from kalcal.io.outputs import writes_outputs
from kalcal.io.results import json_document, write_json
from kalcal.io.statistics import write_statistics
from kalcal.jobs.progress import JobProgress, stage

if TYPE_CHECKING:
    from kalcal.jobs.verify import Verification


@dataclass(frozen=True)
class SavedVerification:
    """What :func:`save_verification` wrote: the files by key, and ``summary.json``'s content as written."""

    paths: dict[str, Path]
    summary: dict[str, Any]


#: the files a verification run (with its report) may write, relative to its folder
OUTPUT_NAMES = ("summary.json", "stats.nc", "stats_long.nc", "report.html", "figures/*.png")


@writes_outputs("verify", names=OUTPUT_NAMES, inputs=("checkpoint",))
def save_verification(
    run: Verification,
    out: str | Path,
    *,
    report: bool = False,
    realization: int = 0,
    progress: JobProgress | None = None,
    checkpoint: str | Path | None = None,
    scenario=None,
) -> SavedVerification:
    """Write a computed verification into ``out`` as one set: ``stats.nc``, ``stats_long.nc`` (with a long
    run), ``summary.json`` and, with ``report``, ``figures/`` and ``report.html`` (realization
    ``realization``). ``checkpoint`` and the files ``scenario`` was read from are never removed.

    ``summary.json``'s ``timing``: ``total_s`` is the computation plus writing the statistics files (s),
    ``report_s`` drawing the figures and page (None without a report), ``wall_s`` both. The page is drawn
    from the summary as it will be written, and ``summary.json`` written once, last.
    """
    del checkpoint, scenario  # protected by the decorator (and the run's own, below)
    return _save(run, Path(out), report=report, realization=realization, progress=progress)


def _save(run: Verification, out: Path, *, report: bool, realization: int, progress) -> SavedVerification:
    writing = time.perf_counter()
    files = 2 if run.long_dataset is None else 3
    paths = {"stats": write_statistics(out / "stats.nc", run.dataset)}
    if run.long_dataset is not None:
        paths["stats_long"] = write_statistics(out / "stats_long.nc", run.long_dataset)
    summary = {**run.summary, "timing": dict(run.summary["timing"])}
    timing = summary["timing"]
    elapsed = run.compute_s + (time.perf_counter() - writing)
    timing.update(total_s=elapsed, report_s=None, wall_s=elapsed)  # no report drawn (yet)
    paths["summary"] = out / "summary.json"  # written last, below
    done = stage(progress, "statistics")
    if done is not None:  # the summary's content is complete: it is written once, after the page
        done(files, files)
    if report:
        from kalcal.jobs import report as report_job  # the page joins this run's set of outputs

        drawing = time.perf_counter()
        # the page is drawn from the summary as it will be written (and as a redraw reads it) and from the
        # statistics in memory, not read back from the files just written: the same bytes as a redraw
        paths["report"] = report_job.draw_report(
            out, json_document(summary), run.dataset, run.long_dataset, realization=realization, progress=progress
        )
        paths["figures"] = out / report_job.FIGURE_DIR
        # the whole job's time, the report included, goes into the staged summary before the set is
        # put in place
        timing["report_s"] = time.perf_counter() - drawing
        timing["wall_s"] = run.compute_s + (time.perf_counter() - writing)
    write_json(paths["summary"], summary)
    return SavedVerification(paths, summary)
