"""write_csv: a table that reads back to the same numbers, every float64 exactly, NaN as an empty field."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from kalcal.io.results import write_csv

EDGES = [np.nan, np.inf, -np.inf, 0.0, -0.0, 1e16, 9999999999999998.0, 1e-4, 1e-5, 5e-324, 2.2250738585072014e-308,
         -1.7976931348623157e308, 0.1, 1 / 3, 1e22, 1.5e-7]  # fmt: skip


def test_the_columns_read_back_bit_for_bit(tmp_path):
    rng = np.random.default_rng(11)
    n = 2_000
    columns = {
        "normal": rng.standard_normal(n) * 10.0 ** rng.integers(-30, 30, n),
        "edges": np.resize(np.array(EDGES), n),
        "int64": rng.integers(-(2**63), 2**63 - 1, n, dtype=np.int64),
    }
    back = pd.read_csv(write_csv(tmp_path / "out" / "t.csv", columns))
    assert list(back.columns) == list(columns)
    for name, values in columns.items():
        read = back[name].to_numpy()
        assert read.dtype == values.dtype, name
        assert np.array_equal(read, values, equal_nan=True) and np.array_equal(np.signbit(read), np.signbit(values)), name


def test_nan_is_an_empty_field_and_lines_end_in_newline(tmp_path):
    text = write_csv(tmp_path / "x.csv", {"a": np.array([0.5, np.nan]), "n": np.arange(2)}).read_bytes()
    assert text == b"a,n\n0.5,0\n,1\n"


def test_columns_of_unequal_lengths_are_refused(tmp_path):
    with pytest.raises(ValueError):
        write_csv(tmp_path / "ragged.csv", {"a": np.zeros(2), "b": np.zeros(3)})
