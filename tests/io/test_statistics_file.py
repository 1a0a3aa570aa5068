"""stats.nc as kalcal writes it: the bytes xarray's scipy writer gives, without importing Dask on the way."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import xarray as xr

from kalcal.analysis.dataset import analysis_dataset
from kalcal.analysis.fixed_gain import analyze_scenario
from kalcal.io.statistics import _encode, read_statistics, write_statistics
from kalcal.jobs.verify import compute_verification
from kalcal.models.registry import build_scenario

SHORT = ["scenario.duration=2"]


@pytest.fixture(scope="module")
def run():
    return compute_verification(build_scenario("accel-gps", None, SHORT), 300, 1, long_run=4.0)


def _datasets(run):
    analysis = analyze_scenario(build_scenario("accel-gps", assignments=["scenario.duration=6"]))
    return {"stats": run.dataset, "stats_long": run.long_dataset, "analysis": analysis_dataset(analysis, {"form": "joseph"})}


@pytest.mark.parametrize("name", ["stats", "stats_long", "analysis"])
def test_the_file_is_byte_for_byte_xarrays(run, tmp_path, name):
    dataset = _datasets(run)[name]
    assert _encode(dataset) is not None  # written by the direct writer, not through to_netcdf
    ours, theirs = tmp_path / "ours.nc", tmp_path / "theirs.nc"
    write_statistics(ours, dataset)
    dataset.to_netcdf(theirs, engine="scipy")
    assert ours.read_bytes() == theirs.read_bytes()
    xr.testing.assert_identical(read_statistics(ours), read_statistics(theirs))


def test_the_dataset_is_the_one_xarrays_own_conversions_build(run):
    for dataset in (run.dataset, run.long_dataset):
        rebuilt = xr.Dataset(
            {name: xr.Variable(v.dims, v.values, v.attrs) for name, v in dataset.data_vars.items()},
            coords={name: (c.dims, c.values.tolist(), c.attrs) for name, c in dataset.coords.items()},
            attrs=dataset.attrs,
        )
        xr.testing.assert_identical(dataset, rebuilt)
        for name, variable in dataset.variables.items():
            assert variable.dtype == rebuilt[name].dtype, name


def test_other_datasets_go_through_xarray(tmp_path):
    dataset = xr.Dataset(
        {"count": ("time", np.array([1, 2, 3])), "flag": ("time", np.array([True, False, True]))},
        coords={"time": ("time", [0.0, 1.0, 2.0], {"units": "s"})},
    )
    assert _encode(dataset) is None
    write_statistics(tmp_path / "other.nc", dataset)
    np.testing.assert_array_equal(read_statistics(tmp_path / "other.nc")["count"].values, [1, 2, 3])


def test_building_and_writing_the_statistics_imports_no_dask_array_or_distributed(tmp_path):
    code = (
        "import sys\n"
        "from kalcal.jobs.verify import compute_verification\n"
        "from kalcal.jobs.verify_save import save_verification\n"
        "from kalcal.models.registry import build_scenario\n"
        f"run = compute_verification(build_scenario('accel-gps', None, {SHORT!r}), 300, 1, long_run=4.0)\n"
        f"save_verification(run, {str(tmp_path / 'out')!r})\n"
        "print(sorted(m for m in ('dask.array', 'distributed', 'matplotlib') if m in sys.modules))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"
    assert (tmp_path / "out" / "stats.nc").is_file() and (tmp_path / "out" / "stats_long.nc").is_file()
