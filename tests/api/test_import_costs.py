"""What each entry point imports: the command line and the API calls load nothing heavy until a job runs,
a verify job loads no more than it uses (no plotting, no Dask, no scipy.stats, scipy.signal or scipy.io), and a
calibration loads matplotlib and numba only for the accel-gps figure and filter."""

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


@pytest.mark.parametrize("module", ["kalcal.jobs.calibrate", "kalcal.jobs.scale_bias"])
def test_the_calibrate_jobs_import_no_plotting_or_compiled_filters(module):
    """matplotlib (the accel-gps figure) and numba (the accel-gps filter) load when an accel-gps run uses them."""
    assert _loaded(module, ("matplotlib", "numba")) == []


def test_a_scale_bias_calibration_loads_no_plotting_or_numba(tmp_path):
    """A scale-bias calibration draws no figure and runs no accel-gps filter: neither is imported."""
    rows = "\n".join(f"{0.1 * i!r},{1.01 * (i % 7) + 0.1 + 0.01 * ((i * 37) % 11 - 5)!r}" for i in range(200))
    (tmp_path / "log.csv").write_text("reference,sensor\n" + rows + "\n")
    code = (
        "import sys, kalcal\n"
        f"kalcal.calibrate('scale-bias', data={str(tmp_path / 'log.csv')!r}, out={str(tmp_path / 'out')!r})\n"
        "print([m for m in ('matplotlib', 'numba') if m in sys.modules])\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "[]"
    assert (tmp_path / "out" / "estimates.csv").is_file()
