"""The seeded statistics of six small runs equal their stored references (``runs.py``), to rounding."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from tests.regression.runs import REFERENCE, RUNS, run

#: rounding, not sampling: a reassociated sum moves the last few bits of a statistic of N = 1000
RTOL = 1e-9


@pytest.mark.parametrize("name", sorted(RUNS))
def test_statistics_equal_the_reference(name, tmp_path):
    with xr.open_dataset(REFERENCE / f"{name}.nc") as stored:
        reference = stored.load()
    actual = run(name, tmp_path / "run")
    assert sorted(actual.data_vars) == sorted(reference.data_vars)
    for key in reference.data_vars:
        expected, got = reference[key].values, actual[key].values
        assert got.shape == expected.shape, key
        scale = float(np.nanmax(np.abs(expected))) if expected.size else 0.0
        np.testing.assert_allclose(got, expected, rtol=RTOL, atol=RTOL * scale, err_msg=key)
    for key in ("scenario", "seed", "engine"):
        assert str(actual.attrs[key]) == str(reference.attrs[key])
