"""stats.nc as kalcal writes it: the bytes xarray's scipy writer gives, without importing Dask on the way; and
as the report reads it back, without xarray."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import xarray as xr

from kalcal.analysis.dataset import analysis_dataset, analysis_parts
from kalcal.analysis.fixed_gain import analyze_scenario
from kalcal.errors import DataError
from kalcal.io.dataset_parts import DatasetParts, Part
from kalcal.io.statistics import _encode, load_statistics, read_statistics, write_statistics
from kalcal.jobs.verify import compute_verification
from kalcal.models.registry import build_scenario

from tests._helpers import last_line_of

SHORT = ["scenario.duration=2"]


@pytest.fixture(scope="module")
def run():
    return compute_verification(build_scenario("accel-gps", None, SHORT), 300, 1, long_run=4.0)


def _datasets(run):
    analysis = analyze_scenario(build_scenario("accel-gps", assignments=["scenario.duration=6"]))
    return {
        "stats": run.dataset.to_xarray(),
        "stats_long": run.long_dataset.to_xarray(),
        "analysis": analysis_dataset(analysis, {"form": "joseph"}),
    }


@pytest.mark.parametrize("name", ["stats", "stats_long", "analysis"])
def test_the_file_is_byte_for_byte_xarrays(run, tmp_path, name):
    dataset = _datasets(run)[name]
    assert _encode(dataset) is not None  # written by the direct writer, not through to_netcdf
    ours, theirs = tmp_path / "ours.nc", tmp_path / "theirs.nc"
    write_statistics(ours, dataset)
    dataset.to_netcdf(theirs, engine="scipy")
    assert ours.read_bytes() == theirs.read_bytes()
    xr.testing.assert_identical(read_statistics(ours), read_statistics(theirs))


def _parts(run, name):
    """The numpy parts a job writes: the verify run's statistics, a scale-bias run's, or the exact analysis's."""
    if name == "analysis":
        analysis = analyze_scenario(build_scenario("accel-gps", assignments=["scenario.duration=6"]))
        return analysis_parts(analysis, {"form": "joseph"})
    if name == "scale_bias":
        return compute_verification(build_scenario("scale-bias", None, ["scenario.duration=4"]), 200, 2).dataset
    return getattr(run, name)


@pytest.mark.parametrize("name", ["dataset", "long_dataset", "analysis"])
def test_the_jobs_parts_are_written_as_the_bytes_of_their_dataset(run, tmp_path, name):
    """The verify and analyze jobs write their files from numpy parts: the file of the Dataset they make."""
    parts = _parts(run, name)
    assert isinstance(parts, DatasetParts)
    assert _encode(parts) is not None
    ours, theirs = tmp_path / "ours.nc", tmp_path / "theirs.nc"
    write_statistics(ours, parts)
    parts.to_xarray().to_netcdf(theirs, engine="scipy")
    assert ours.read_bytes() == theirs.read_bytes()


def test_the_parts_answer_as_their_dataset(run):
    """What the jobs ask of the parts (sizes, dims, variables in order, values, membership) is what the
    Dataset they make answers."""
    for parts in (run.dataset, run.long_dataset, _parts(run, "analysis")):
        dataset = parts.to_xarray()
        assert parts.sizes == dict(dataset.sizes) and set(parts.dims) == set(dataset.dims)
        assert list(parts.variables) == list(dataset.variables)
        assert list(parts.coords) == list(dataset.coords) and list(parts.data_vars) == list(dataset.data_vars)
        for name, part in parts.variables.items():
            assert part.dims == dataset[name].dims, name
            np.testing.assert_array_equal(part.values, dataset[name].values)
        assert "mean_nis" in parts and "time" in parts and "no_such_variable" not in parts
        assert dict(parts.attrs) == dataset.attrs


def test_parts_whose_dimensions_disagree_are_refused():
    parts = DatasetParts(
        {"a": Part.of("time", [1.0, 2.0]), "b": Part.of("time", [1.0, 2.0, 3.0])}, {}, {}
    )
    with pytest.raises(ValueError, match="b: dimension time has length 3, elsewhere 2"):
        parts.to_xarray()
    with pytest.raises(ValueError, match="2 dimension names for 1"):
        DatasetParts({"a": Part.of(("time", "state"), [1.0])}, {}).sizes


def test_the_dataset_is_the_one_xarrays_own_conversions_build(run):
    for dataset in (run.dataset.to_xarray(), run.long_dataset.to_xarray()):
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


def test_building_and_writing_the_statistics_imports_no_xarray_pandas_or_dask(tmp_path):
    """The job keeps its statistics as numpy parts and writes them through scipy: no xarray (nor the pandas
    and Dask it brings) in a verify job's process."""
    code = (
        "import sys\n"
        "from kalcal.jobs.verify import compute_verification\n"
        "from kalcal.jobs.verify_save import save_verification\n"
        "from kalcal.models.registry import build_scenario\n"
        f"run = compute_verification(build_scenario('accel-gps', None, {SHORT!r}), 300, 1, long_run=4.0)\n"
        f"save_verification(run, {str(tmp_path / 'out')!r})\n"
        "print(sorted(m for m in ('dask', 'distributed', 'matplotlib', 'xarray', 'pandas') if m in sys.modules))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"
    assert (tmp_path / "out" / "stats.nc").is_file() and (tmp_path / "out" / "stats_long.nc").is_file()


def test_kalcal_verify_makes_its_dataset_only_when_statistics_is_read():
    code = (
        "import sys, kalcal\n"
        "r = kalcal.verify('accel-gps', 300, 1, settings={'scenario.duration': 2}, long_run=4.0)\n"
        "before = 'xarray' in sys.modules\n"
        "import xarray as xr\n"
        "print(before, isinstance(r.statistics, xr.Dataset), r.statistics is r.statistics,"
        " dict(r.long_statistics.sizes)['time'])\n"
    )
    assert last_line_of(code) == "False True True 20"


@pytest.mark.parametrize("name", ["dataset", "long_dataset", "analysis", "scale_bias"])
def test_the_files_kalcal_writes_load_as_parts_with_xarrays_values(run, tmp_path, name):
    """The report reads a run's files without xarray: the variables (data and coordinates, in the file's
    order), dimensions, values, attributes and global attributes xarray reads, labels as str arrays."""
    path = tmp_path / "stats.nc"
    write_statistics(path, _parts(run, name))
    parts, dataset = load_statistics(path), read_statistics(path)
    assert isinstance(parts, DatasetParts)
    assert list(parts.data_vars) == list(dataset.data_vars) and list(parts.coords) == list(dataset.coords)
    for key in dataset.variables:
        assert parts[key].dims == dataset[key].dims and parts[key].attrs == dataset[key].attrs, key
        if dataset[key].dtype == object:  # xarray's labels are objects; the parts' str, the same words
            assert parts[key].values.dtype.kind == "U" and parts[key].values.tolist() == dataset[key].values.tolist()
        else:
            assert parts[key].values.dtype == dataset[key].values.dtype == np.float64, key
            np.testing.assert_array_equal(parts[key].values, dataset[key].values)
    assert parts.attrs == dataset.attrs
    assert all(type(parts.attrs[key]) is type(value) for key, value in dataset.attrs.items())


def test_a_file_kalcal_did_not_write_loads_through_xarray(tmp_path):
    """A variable xarray would decode (scale_factor) or of another type (integers): read_statistics's
    Dataset, decoded as xarray decodes it; a file that is not NetCDF is a DataError, as there."""
    scaled = tmp_path / "scaled.nc"
    xr.Dataset({"a": ("time", np.array([1.0, 2.0]), {"scale_factor": 2.0})}).to_netcdf(scaled, engine="scipy")
    loaded = load_statistics(scaled)
    assert isinstance(loaded, xr.Dataset)
    np.testing.assert_array_equal(loaded["a"].values, [2.0, 4.0])  # decoded by xarray: the stored values times 2
    others = {
        "counts": xr.Dataset({"n": ("time", np.array([1, 2], dtype=np.int32))}),
        "single": xr.Dataset({"a": ("time", np.array([1.0, 2.0], dtype=np.float32))}),
        "timedelta": xr.Dataset({"a": ("time", np.array([1.0, 2.0]), {"units": "seconds"})}),
        # a label over dimensions no variable has: xarray writes a global "coordinates" attribute
        "global_coordinates": xr.Dataset({"a": ("x", [1.0, 2.0])}, coords={"label": ("y", ["p", "q"])}),
    }
    for name, other in others.items():
        path = tmp_path / f"{name}.nc"
        other.to_netcdf(path, engine="scipy")
        assert isinstance(load_statistics(path), xr.Dataset), name
    assert "label" in load_statistics(tmp_path / "global_coordinates.nc").coords
    from scipy.io import netcdf_file

    for where in ("global", "variable"):  # attributes that are not UTF-8: xarray reads them its own way
        path = tmp_path / f"latin1_{where}.nc"
        with netcdf_file(path, mode="w", version=2) as file:
            file.createDimension("time", 2)
            variable = file.createVariable("a", np.dtype(">f8"), ["time"])
            variable._FillValue = np.nan
            variable[:] = [1.0, 2.0]
            setattr(file if where == "global" else variable, "note", "caf\xe9".encode("latin-1"))
        assert isinstance(load_statistics(path), xr.Dataset), where
    bad = tmp_path / "bad.nc"
    bad.write_text("not netcdf")
    with pytest.raises(DataError, match="not a kalcal statistics file"):
        load_statistics(bad)
    with pytest.raises(DataError, match="no such statistics file"):
        load_statistics(tmp_path / "missing.nc")


@pytest.mark.filterwarnings("ignore")  # xarray warns of what it makes of some corrupt headers
def test_a_cut_or_corrupt_file_is_one_data_error_in_either_reader(run, tmp_path):
    """A file cut anywhere in its header or data, or with a word of its header overwritten (a seeded
    fuzz, 300 files), is read or refused in one DataError by both readers, never a traceback: scipy's
    reader meets them with IndexError, KeyError, ValueError, OSError and TypeError, each of them met here."""
    import random
    import struct

    from scipy.io import netcdf_file

    whole = tmp_path / "whole.nc"
    write_statistics(whole, run.dataset)
    data = whole.read_bytes()
    cut = tmp_path / "cut.nc"
    for end in [*range(0, 5000, 7), len(data) // 2, len(data) - 64]:  # the header is 3-5 kB; the last bytes may be padding
        cut.write_bytes(data[:end])
        for reader in (load_statistics, read_statistics):
            with pytest.raises(DataError, match=r"cut\.nc: not a kalcal statistics file"):
                reader(cut)
    rng, raised = random.Random(0), set()
    for _ in range(300):
        corrupt = bytearray(data)
        at = rng.randrange(0, 3000 // 4) * 4
        corrupt[at:at + 4] = struct.pack(">I", rng.choice([0x7FFFFFFF, 0xFFFFFFFF, 0, 1, 2, 7, 99, rng.randrange(2**32)]))
        cut.write_bytes(bytes(corrupt))
        try:
            netcdf_file(cut, mmap=False).close()
        except Exception as exc:  # what the readers must turn into a DataError
            raised.add(type(exc))
        for reader in (load_statistics, read_statistics):
            try:
                reader(cut)
            except DataError:
                pass
    assert {IndexError, KeyError, ValueError, OSError, TypeError} <= raised
