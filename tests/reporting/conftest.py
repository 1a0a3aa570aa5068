"""A small saved verification run with its report, made once per test session, for the report tests.

Under pytest-xdist every worker would build its own; a lock file in the directory the workers share
lets the first build it and the others reuse it. Tests must not change the shared run: those that
render again or remove files work on a copy (:func:`copy_run`).
"""

import contextlib
import fcntl
import os
import shutil

import pytest

from kalcal.api.verification import verify
from kalcal.scenarios import build_scenario

N = 5000
SEED = 3
REALIZATION = 4321  # in the short last block of the ensemble (4096 + 904)
COMMAND = "kalcal verify -n 5000 --seed 3 --set scenario.duration=6"
# with the manifest of the files kalcal wrote there: a copy of a run folder (cp -r) carries it
RUN_FILES = ("summary.json", "stats.nc", "stats_long.nc", ".kalcal-manifest.json")


@contextlib.contextmanager
def _locked(path):
    with open(path, "w") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


@pytest.fixture(scope="session")
def report_run(tmp_path_factory):
    """A 6 s run of N = 5000 with a 12 s long run, and the page its job drew: (directory, page path)."""
    base = tmp_path_factory.getbasetemp()
    shared = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base
    out = shared / "kalcal-report-run"
    with _locked(shared / "kalcal-report-run.lock"):
        page = out / "report.html"
        if not page.is_file():
            scenario = build_scenario("accel-gps", None, ["scenario.duration=6"])
            # the page as the job draws it, from the run in memory (a redraw gives the same bytes:
            # test_report_job.py::test_render_twice_gives_identical_page_and_figures)
            verify(scenario, N, SEED, out, long_run=12.0, command=COMMAND, report=True, realization=REALIZATION)
    return out, page


@pytest.fixture
def copy_run(report_run, tmp_path):
    """make(exclude=(), figures=False): a private copy of the saved run, without the files in ``exclude``,
    with or without its figures and page."""

    def make(*, exclude=(), figures=False):
        target = tmp_path / "run"
        target.mkdir()
        for name in RUN_FILES:
            if name not in exclude:
                shutil.copy2(report_run[0] / name, target / name)
        if figures:
            shutil.copytree(report_run[0] / "figures", target / "figures")
            shutil.copy2(report_run[0] / "report.html", target / "report.html")
        return target

    return make
