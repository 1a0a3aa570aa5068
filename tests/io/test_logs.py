"""Log readers: every problem is a DataError naming the file, the column, the row and the value."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from kalcal.errors import DataError
from kalcal.io.logs import numeric_columns, read_table, require_increasing
from kalcal.io.results import SCHEMA_VERSION, to_jsonable, write_csv, write_json


def _write(path, text):
    path.write_text(text)
    return path


def test_csv_and_parquet_read_the_same(tmp_path):
    frame = pd.DataFrame({"time": [0.0, 0.005, 0.01], "accel": [0.1, -0.2, 1e-17]})
    frame.to_csv(tmp_path / "imu.csv", index=False, float_format="%.17g")
    frame.to_parquet(tmp_path / "imu.parquet")
    frame.to_parquet(tmp_path / "imu.pq")
    for name in ("imu.csv", "imu.parquet", "imu.pq"):
        columns = numeric_columns(read_table(tmp_path / name), name, ("time", "accel"))
        np.testing.assert_array_equal(columns["time"], frame["time"].to_numpy())
        np.testing.assert_array_equal(columns["accel"], frame["accel"].to_numpy())
        assert columns["time"].dtype == float


def test_header_whitespace_is_ignored(tmp_path):
    path = _write(tmp_path / "a.csv", "time, accel\n0, 1.5\n0.005, 2\n")
    columns = numeric_columns(read_table(path), path, ("time", "accel"))
    np.testing.assert_array_equal(columns["accel"], [1.5, 2.0])


def test_integer_columns_become_floats(tmp_path):
    path = _write(tmp_path / "a.csv", "time,accel\n0,1\n1,2\n")
    columns = numeric_columns(read_table(path), path, ("time", "accel"))
    assert columns["accel"].dtype == float


def test_role_mapping(tmp_path):
    path = _write(tmp_path / "a.csv", "t,acc\n0,1\n")
    columns = numeric_columns(read_table(path), path, {"time": "t", "accel": "acc"})
    assert set(columns) == {"time", "accel"}
    with pytest.raises(DataError, match=r"a\.csv: missing column 'x' for time"):
        numeric_columns(read_table(path), path, {"time": "x"})


@pytest.mark.parametrize(
    "name, text, pattern",
    [
        ("missing.csv", None, r"missing\.csv: no such file"),
        ("empty.csv", "", r"empty\.csv: file is empty"),
        ("header.csv", "time,accel\n", r"header\.csv: has a header but no data rows"),
        ("log.txt", "time,accel\n0,1\n", r"log\.txt: unknown file type '\.txt'"),
    ],
)
def test_read_table_errors(tmp_path, name, text, pattern):
    path = tmp_path / name
    if text is not None:
        path.write_text(text)
    with pytest.raises(DataError, match=pattern):
        read_table(path)


def test_directory_is_not_a_file(tmp_path):
    folder = tmp_path / "dir.csv"
    folder.mkdir()
    with pytest.raises(DataError, match="no such file"):
        read_table(folder)


def test_corrupt_parquet_is_data_error(tmp_path):
    path = _write(tmp_path / "bad.parquet", "this is not parquet")
    with pytest.raises(DataError, match=r"bad\.parquet: cannot be read as parquet"):
        read_table(path)


@pytest.mark.parametrize(
    "text, pattern",
    [
        ("time,acc\n0,1\n", r"missing column 'accel' \(columns: time, acc\)"),
        ("time,accel\n0,1\n0.005,abc\n", r"row 2, column 'accel': not a number: 'abc'"),
        ("time,accel\n0,1\n0.005,nan\n", r"row 2, column 'accel': .*expected a finite number"),
        ("time,accel\n0,1\n0.005,\n", r"row 2, column 'accel': .*expected a finite number"),
        ("time,accel\n0,inf\n", r"row 1, column 'accel': .*expected a finite number"),
        ("time,accel\n0,1\n0.005,-inf\n", r"row 2, column 'accel': .*expected a finite number"),
        ("time,accel\n0,1\nx,2\n", r"row 2, column 'time': not a number: 'x'"),
    ],
)
def test_numeric_column_errors(tmp_path, text, pattern):
    path = _write(tmp_path / "imu.csv", text)
    with pytest.raises(DataError, match=r"imu\.csv: " + pattern):
        numeric_columns(read_table(path), path, ("time", "accel"))


def test_allow_nan_keeps_nan_but_not_inf(tmp_path):
    path = _write(tmp_path / "g.csv", "time,position\n0,1\n1,\n2,nan\n")
    columns = numeric_columns(read_table(path), path, ("time", "position"), allow_nan=("position",))
    assert np.isnan(columns["position"][1]) and np.isnan(columns["position"][2])
    path = _write(tmp_path / "h.csv", "time,position\n0,1\n1,inf\n")
    with pytest.raises(DataError, match="row 2"):
        numeric_columns(read_table(path), path, ("time", "position"), allow_nan=("position",))


@pytest.mark.parametrize(
    "time, row",
    [
        ([0.0, 0.1, 0.1, 0.3], 3),  # repeated
        ([0.0, 0.1, 0.05, 0.3], 3),  # going back
        ([0.0, 0.1, 0.2, np.nan], 4),
    ],
)
def test_require_increasing_names_the_row(time, row):
    with pytest.raises(DataError, match=rf"imu\.csv: row {row}, column 'time'.*does not increase"):
        require_increasing(np.array(time), "imu.csv")


def test_require_increasing_accepts_increasing_and_single_rows():
    require_increasing(np.array([0.0, 0.1, 0.2]), "x")
    require_increasing(np.array([5.0]), "x")


def test_write_csv_round_trips_full_precision(tmp_path):
    values = np.array([0.1, 1 / 3, np.pi * 1e-17, -2.5e300])
    path = write_csv(tmp_path / "sub" / "out.csv", {"a": values, "b": np.arange(4.0)})
    frame = pd.read_csv(path)
    assert list(frame.columns) == ["a", "b"]
    np.testing.assert_array_equal(frame["a"].to_numpy(), values)


def test_write_json_and_to_jsonable(tmp_path):
    document = {"a": np.float64(1.5), "b": np.arange(3), "c": np.nan, "d": np.bool_(True), "e": (np.int64(2),)}
    assert to_jsonable(document) == {"a": 1.5, "b": [0, 1, 2], "c": None, "d": True, "e": [2]}
    path = write_json(tmp_path / "s.json", document)
    assert json.loads(path.read_text()) == {
        "schema_version": SCHEMA_VERSION,
        "a": 1.5,
        "b": [0, 1, 2],
        "c": None,
        "d": True,
        "e": [2],
        "nonfinite": {"count": 1, "fields": {"c": 1}},
    }
    assert not (tmp_path / "s.json.tmp").exists()


def test_every_nonfinite_value_written_as_null_is_counted_by_field(tmp_path):
    """JSON has no NaN: each one written as null is counted under its field, so that none is silent."""
    document = {
        "final": {"cov": np.array([[1.0, np.nan], [np.inf, -np.inf]]), "mean": [0.0, 1.0]},
        "tests": [{"statistic": np.float64(np.nan)}, {"statistic": 2.0}, {"statistic": float("nan")}],
        "ok": 3.0,
    }
    counted: dict[str, int] = {}
    plain = to_jsonable(document, counted)
    assert plain["final"]["cov"] == [[1.0, None], [None, None]]
    assert counted == {"final.cov": 3, "tests.statistic": 2}
    written = json.loads(write_json(tmp_path / "s.json", document).read_text())
    assert written["nonfinite"] == {"count": 5, "fields": {"final.cov": 3, "tests.statistic": 2}}
    assert list(written)[0] == "schema_version" and written["schema_version"] == SCHEMA_VERSION == 1
    clean = json.loads(write_json(tmp_path / "t.json", {"ok": 3.0}).read_text())
    assert clean["nonfinite"] == {"count": 0, "fields": {}}


@pytest.mark.parametrize("case", ["inf cell", "non-increasing time"])
def test_values_in_messages_are_plain_numbers(tmp_path, case):
    if case == "inf cell":
        path = _write(tmp_path / "imu.csv", "time,accel\n0,1\n0.005,inf\n")
        with pytest.raises(DataError) as info:
            numeric_columns(read_table(path), path, ("time", "accel"))
    else:
        with pytest.raises(DataError) as info:
            require_increasing(np.array([0.0, 0.5, 0.25]), "imu.csv")
    assert "np." not in str(info.value), str(info.value)
