"""The page a verify job draws from its run in memory is the page ``kalcal report DIR`` redraws from its files."""

import os
import shutil
import sys

import pytest

from kalcal.reporting import render as report_job
from kalcal.api.verification import verify
from kalcal.scenarios import build_scenario

RUN_FILES = ("summary.json", "stats.nc", "stats_long.nc", ".kalcal-manifest.json")


#: while true, opening a NetCDF file fails: an audit hook stays for the rest of the process, so it is
#: installed once and does nothing while this is false
_REFUSING = False
#: the NetCDF files this process tried to open while refused (a reader might swallow the error)
_OPENED: list[str] = []
_HOOKED = False


def _refuse_nc(event, args):
    if not _REFUSING or event != "open" or not isinstance(args[0], (str, bytes, os.PathLike)):
        return
    if os.fsdecode(args[0]).endswith(".nc"):
        _OPENED.append(os.fsdecode(args[0]))
        raise AssertionError(f"{os.fsdecode(args[0])} opened while the job drew its page")


def _refusing_nc(draw):
    """``draw`` with every open of a ``*.nc`` file refused while it runs: Python's ``open``, ``os.open``
    (and so scipy's netcdf_file, which xarray's scipy engine reads through) raise the ``open`` audit
    event, where the refusal fails the figure and so the job."""
    global _HOOKED

    if not _HOOKED:
        sys.addaudithook(_refuse_nc)
        _HOOKED = True

    def refused(*args, **kwargs):
        global _REFUSING
        _REFUSING = True
        try:
            return draw(*args, **kwargs)
        finally:
            _REFUSING = False

    return refused


def test_the_hook_refuses_a_statistics_file(tmp_path):
    path = tmp_path / "stats.nc"
    path.write_bytes(b"CDF")
    with pytest.raises(AssertionError, match="stats.nc opened while the job drew its page"):
        _refusing_nc(report_job.read_statistics)(path)
    assert _OPENED.pop() == str(path) and not _REFUSING and path.read_bytes() == b"CDF"  # off again


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
    # nor opened at all, through any reader, while the job draws (its stats.nc is written before)
    monkeypatch.setattr(report_job, "draw_report", _refusing_nc(report_job.draw_report))
    _OPENED.clear()
    job = tmp_path / "job"
    verify(build_scenario("scale-bias", None, ["scenario.duration=20"]), 300, 2, job, long_run=0, report=True, realization=7)
    assert read == [] and _OPENED == []  # the job's page: the statistics in memory, not read back
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
