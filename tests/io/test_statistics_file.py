"""stats.nc and analysis.nc as kalcal writes them through xarray, and as the report reads them back."""

from __future__ import annotations

import pytest
import xarray as xr

from kalcal.analysis.dataset import analysis_dataset
from kalcal.analysis.fixed_gain import analyze_scenario
from kalcal.errors import DataError
from kalcal.io.statistics import read_statistics, write_statistics
from kalcal.api.verification import compute_verification
from kalcal.scenarios import build_scenario

SHORT = ["scenario.duration=2"]


@pytest.fixture(scope="module")
def run():
    return compute_verification(build_scenario("accel-gps", None, SHORT), 300, 1, long_run=4.0)


def _datasets(run):
    analysis = analyze_scenario(build_scenario("accel-gps", assignments=["scenario.duration=6"]))
    return {"stats": run.statistics, "stats_long": run.long_statistics, "analysis": analysis_dataset(analysis, {"form": "joseph"})}


@pytest.mark.parametrize("name", ["stats", "stats_long", "analysis"])
def test_a_written_file_reads_back_as_its_dataset(run, tmp_path, name):
    dataset = _datasets(run)[name]
    path = write_statistics(tmp_path / "deep" / f"{name}.nc", dataset)
    back = read_statistics(path)
    xr.testing.assert_identical(back, dataset)


def test_a_missing_file_is_one_data_error(tmp_path):
    with pytest.raises(DataError, match="no such statistics file"):
        read_statistics(tmp_path / "missing.nc")


@pytest.mark.filterwarnings("ignore")  # xarray warns of what it makes of some corrupt headers
def test_a_cut_or_corrupt_file_is_one_data_error(run, tmp_path):
    """A file cut anywhere in its header or data, or with a word of its header overwritten (a seeded
    fuzz, 300 files), is read or refused in one DataError, never a traceback: scipy's
    reader meets them with IndexError, KeyError, ValueError, OSError and TypeError, each of them met here."""
    import random
    import struct

    from scipy.io import netcdf_file

    whole = tmp_path / "whole.nc"
    write_statistics(whole, run.statistics)
    data = whole.read_bytes()
    cut = tmp_path / "cut.nc"
    for end in [*range(0, 5000, 7), len(data) // 2, len(data) - 64]:  # the header is 3-5 kB; the last bytes may be padding
        cut.write_bytes(data[:end])
        with pytest.raises(DataError, match=r"cut\.nc: not a kalcal statistics file"):
            read_statistics(cut)
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
        try:
            read_statistics(cut)
        except DataError:
            pass
    assert {IndexError, KeyError, ValueError, OSError, TypeError} <= raised
