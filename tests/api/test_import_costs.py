"""What each entry point imports: the command line and the API calls load nothing heavy until a job runs,
and a verify job loads no more than it uses (no plotting, no Dask, no scipy.stats, scipy.signal or scipy.io)."""

from __future__ import annotations

import subprocess
import sys

import pytest

HEAVY = ("pandas", "xarray", "numba", "matplotlib", "dask", "dask.array", "distributed", "scipy")


def _loaded(module: str, watched: tuple[str, ...]) -> list[str]:
    code = f"import sys, {module}; print([m for m in {watched!r} if m in sys.modules])"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return eval(done.stdout.strip())  # a list of names printed by the child


@pytest.mark.parametrize("module", ["kalcal.cli", "kalcal.api.verify", "kalcal.api.calibrate"])
def test_the_command_line_and_the_api_calls_import_nothing_heavy(module):
    assert _loaded(module, HEAVY) == []


def test_the_command_line_imports_no_numpy():
    assert _loaded("kalcal.cli", ("numpy", *HEAVY)) == []


def test_the_verify_job_imports_no_plotting_dask_or_unused_scipy():
    watched = ("matplotlib", "dask", "dask.array", "distributed", "scipy.stats", "scipy.signal", "scipy.io", "scipy.optimize")
    assert _loaded("kalcal.jobs.verify", watched) == []
