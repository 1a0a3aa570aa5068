"""The page a verify job draws from its run in memory is the page ``kalcal report DIR`` redraws from its files."""

import shutil

from kalcal.jobs import report as report_job
from kalcal.jobs.verify import verify
from kalcal.models.registry import build_scenario

RUN_FILES = ("summary.json", "stats.nc", "stats_long.nc", ".kalcal-manifest.json")


def _drawn(folder):
    return {
        path.relative_to(folder).as_posix(): path.read_bytes()
        for path in [folder / "report.html", *(folder / "figures").glob("*.png")]
    }


def test_the_jobs_page_is_the_redraws_bytes(tmp_path, monkeypatch):
    """Another scenario than the shared run's (accel-gps with a long run: test_report_job.py), without a long run."""
    read = []
    real_read = report_job.read_statistics
    monkeypatch.setattr(report_job, "read_statistics", lambda path: read.append(path) or real_read(path))
    job = tmp_path / "job"
    verify(build_scenario("scale-bias", None, ["scenario.duration=20"]), 300, 2, job, long_run=0, report=True, realization=7)
    assert read == []  # the job's page: the statistics in memory, not read back
    redraw = tmp_path / "redraw"
    redraw.mkdir()
    for file in RUN_FILES:
        if (job / file).is_file():
            shutil.copy2(job / file, redraw / file)
    report_job.render_report(redraw, realization=7)
    assert read  # the redraw: the files
    drawn = _drawn(job)
    assert len(drawn) >= 8
    assert drawn == _drawn(redraw)
