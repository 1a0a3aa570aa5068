"""The analysis as a Dataset (named dimensions, units, NetCDF round trip), its JSON parts, and its figures."""

from __future__ import annotations

import json
import struct

import numpy as np
import xarray as xr

from kalcal.analysis.dataset import analysis_dataset, budget_summary, final_summary
from kalcal.analysis.fixed_gain import analyze_scenario
from kalcal.scenarios import build_scenario
from kalcal.plots.analysis import plot_budget, plot_sigma

SETTINGS = ["scenario.duration=6", "truth.accel_noise_std=0.04", "filter.accel_noise_std=0.02", "truth.bias_walk_std=2e-4"]


def _result():
    return analyze_scenario(build_scenario("accel-gps", assignments=SETTINGS))


def test_dataset_has_named_dimensions_and_units_and_round_trips(tmp_path):
    result = _result()
    ds = analysis_dataset(result)
    assert ds["error_covariance"].dims == ("update", "state", "state_col")
    assert ds["residual_second_moment"].dims == ("update", "measurement", "update_col", "measurement_col")
    assert ds["budget"].dims == ("source", "update", "state", "state_col")
    assert list(ds["kind"].values) == [t.kind for t in result.budget]
    assert all("units" in ds[v].attrs and "long_name" in ds[v].attrs for v in ds.data_vars)
    np.testing.assert_allclose(ds["budget"].sum("source"), ds["error_covariance"], rtol=1e-9, atol=1e-15)
    ds.to_netcdf(tmp_path / "analysis.nc", engine="scipy")
    with xr.open_dataset(tmp_path / "analysis.nc", engine="scipy") as back:
        np.testing.assert_array_equal(back["mean_nees"].values, result.mean_nees)
        assert list(back["source"].values) == [t.source for t in result.budget]


def test_final_and_budget_are_json_and_sum_to_the_final_covariance():
    result = _result()
    final, budget = final_summary(result), budget_summary(result)
    json.dumps({"final": final, "budget": budget}, allow_nan=False)
    assert final["time"] == 6.0 and final["states"] == ["position", "velocity", "bias"]
    total = np.sum([b["final"] for b in budget], axis=0)
    np.testing.assert_allclose(total, final["error_covariance"], rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(np.sum([b["variance_fraction"] for b in budget], axis=0), 1.0, rtol=1e-9)
    assert {b["kind"] for b in budget} == {"prior", "process", "measurement"}


def test_figures_are_pngs_of_their_documented_size(tmp_path):
    ds = analysis_dataset(_result())
    for draw in (plot_sigma, plot_budget):
        path = draw(ds, tmp_path / f"{draw.__name__}.png")
        data = path.read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n"
        assert struct.unpack(">II", data[16:24]) == (900, 150 + 250 * 3)
        assert draw(ds, tmp_path / "again.png").read_bytes() == data
