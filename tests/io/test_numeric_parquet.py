"""A Parquet log of numbers is read without pandas (kalcal.io.logs.NumericTable): the same columns as
pandas' frame gives numeric_columns (bit for bit but for a null's NaN payload), and anything else is
still read by pandas."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from kalcal.errors import DataError
from kalcal.io.logs import NumericTable, _numeric_parquet, numeric_columns, read_table


def _through_pandas(path, names):
    """What numeric_columns took from pandas' frame of the file (the reader before NumericTable)."""
    frame = pd.read_parquet(path)
    frame.columns = [str(c).strip() for c in frame.columns]
    return numeric_columns(frame, path, names, allow_nan=names)


def _assert_same(path, names):
    table = read_table(path)
    assert isinstance(table, NumericTable)
    ours, theirs = numeric_columns(table, path, names, allow_nan=names), _through_pandas(path, names)
    for name in names:
        assert ours[name].dtype == np.float64 and ours[name].flags.writeable
        nan = np.isnan(theirs[name])
        np.testing.assert_array_equal(np.isnan(ours[name]), nan)  # NaN where pandas has NaN (payloads may differ)
        np.testing.assert_array_equal(ours[name][~nan].view(np.uint64), theirs[name][~nan].view(np.uint64))  # bits


def test_numbers_of_every_width_with_nulls_read_as_pandas_reads_them(tmp_path):
    rng = np.random.default_rng(5)
    n = 1000
    nulls = rng.random(n) < 0.1
    big = rng.integers(-(2**63), 2**63 - 1, n, dtype=np.int64)  # beyond 2**53: rounded as numpy rounds
    columns = {
        "f64": pa.array(rng.integers(0, 2**64, n, dtype=np.uint64).view(np.float64), mask=nulls),  # any bits, NaN too
        "f32": pa.array(rng.standard_normal(n).astype(np.float32), mask=nulls),
        "f16": pa.array(rng.standard_normal(n).astype(np.float16), mask=nulls),
        "i64": pa.array(big, mask=nulls),
        "i64_full": pa.array(big),
        "u64": pa.array(rng.integers(0, 2**64, n, dtype=np.uint64)),
        "i8": pa.array(rng.integers(-128, 127, n, dtype=np.int8), mask=nulls),
        " padded ": pa.array(rng.standard_normal(n)),
    }
    path = tmp_path / "log.parquet"
    pq.write_table(pa.table(columns), path, row_group_size=97)
    _assert_same(path, ["f64", "f32", "f16", "i64", "i64_full", "u64", "i8", "padded"])


def test_a_frame_written_by_pandas_with_its_range_index_reads_as_numbers(tmp_path):
    frame = pd.DataFrame({"time": np.arange(5) * 0.005, "accel": [0.1, np.nan, 1e-300, -0.0, 3]})
    frame.to_parquet(tmp_path / "imu.parquet")
    _assert_same(tmp_path / "imu.parquet", ["time", "accel"])
    pd.DataFrame({"n": pd.array([1, None, 3], dtype="Int64")}).to_parquet(tmp_path / "nullable.parquet")
    _assert_same(tmp_path / "nullable.parquet", ["n"])


def test_sliced_arrays_are_read_from_their_offset():
    """Arrow arrays may start inside their buffers (a slice): values and nulls from the offset on."""
    values = pa.array([1.0, 2.0, None, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, None, 11.0]).slice(2, 8)
    ints = pa.array([1, 2, 3, None, 5, 6, 7, 8, 9, 10, 11]).slice(3, 8)
    table = _numeric_parquet(pa.table({"x": values, "n": ints}))
    np.testing.assert_array_equal(table["x"], [np.nan, 4, 5, 6, 7, 8, 9, np.nan])
    np.testing.assert_array_equal(table["n"], [np.nan, 5, 6, 7, 8, 9, 10, 11])
    assert len(table) == 8 and table.columns == ("x", "n")
    chunked = pa.chunked_array([pa.array([1.0, None, 3.0]).slice(1), pa.array([4, None], pa.int32()).cast(pa.float64())])
    np.testing.assert_array_equal(_numeric_parquet(pa.table({"x": chunked}))["x"], [np.nan, 3, 4, np.nan])


@pytest.mark.parametrize(
    "case",
    ["text column", "bool column", "timestamp column", "stored index", "two-level columns", "names repeat once stripped"],
)
def test_anything_else_is_read_by_pandas(tmp_path, case):
    path = tmp_path / "log.parquet"
    frame = pd.DataFrame({"time": [0.0, 1.0], "accel": [0.5, 0.25]})
    if case == "text column":
        frame["label"] = ["a", "b"]
    elif case == "bool column":
        frame["flag"] = [True, False]
    elif case == "timestamp column":
        frame["stamp"] = pd.to_datetime(["2026-01-01", "2026-01-02"])
    elif case == "stored index":
        frame.index = pd.Index([10, 20], name="row")
    elif case == "two-level columns":
        frame.columns = pd.MultiIndex.from_tuples([("time", "s"), ("accel", "m/s2")])
    if case == "names repeat once stripped":
        pq.write_table(pa.table({"time": [0.0, 1.0], "accel": [0.5, 0.25], " accel": [1.0, 2.0]}), path)
    else:
        frame.to_parquet(path)
    table = read_table(path)
    assert isinstance(table, pd.DataFrame)
    if case in ("text column", "bool column", "timestamp column", "stored index"):
        columns = numeric_columns(table, path, ("time", "accel"))
        np.testing.assert_array_equal(columns["accel"], [0.5, 0.25])
    if case == "stored index":
        assert list(table.columns) == ["time", "accel"]  # the index is not a column of the log


def test_the_messages_of_a_numeric_parquet_file_are_those_of_a_frame(tmp_path):
    (tmp_path / "zero.parquet").write_bytes(b"")
    with pytest.raises(DataError, match=r"zero\.parquet: cannot be read as parquet"):
        read_table(tmp_path / "zero.parquet")
    pq.write_table(pa.table({"time": pa.array([], pa.float64()), "accel": pa.array([], pa.float64())}), tmp_path / "e.parquet")
    with pytest.raises(DataError, match=r"e\.parquet: has a header but no data rows"):
        read_table(tmp_path / "e.parquet")
    pq.write_table(pa.table({"time": [0.0, 1.0, 2.0], "accel": [1.0, None, np.inf]}), tmp_path / "a.parquet")
    table = read_table(tmp_path / "a.parquet")
    with pytest.raises(DataError, match=r"missing column 'x' \(columns: time, accel\)"):
        numeric_columns(table, "a.parquet", ("x",))
    with pytest.raises(DataError, match=r"a\.parquet: row 3, column 'accel': value is inf, expected a finite number"):
        numeric_columns(table, "a.parquet", ("accel",), allow_nan=("accel",))
    with pytest.raises(DataError, match=r"a\.parquet: row 2, column 'accel': value is nan"):  # a null, not allowed
        numeric_columns(table, "a.parquet", ("time", "accel"))
