"""write_csv without pandas: the bytes of DataFrame.to_csv(index=False), for every float64 bit pattern
drawn and every edge (NaN, infinities, -0.0, the switches to exponent form, subnormals, integers)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from kalcal.io.results import write_csv

EDGES = [np.nan, np.inf, -np.inf, 0.0, -0.0, 1e16, 9999999999999998.0, 1e-4, 1e-5, 0.0001234, 5e-324, 2.2250738585072014e-308,
         -1.7976931348623157e308, 0.1, 1 / 3, 123456789.0, 1e22, 1.5e-7]  # fmt: skip


def _pandas_bytes(tmp_path, columns):
    path = tmp_path / "pandas.csv"
    pd.DataFrame(columns).to_csv(path, index=False, lineterminator="\n")
    return path.read_bytes()


def test_random_bit_patterns_and_edges_are_written_as_pandas_writes_them(tmp_path):
    rng = np.random.default_rng(11)
    n = 20_000
    columns = {
        "bits": rng.integers(0, 2**64, n, dtype=np.uint64).view(np.float64),  # NaNs of any payload among them
        "normal": rng.standard_normal(n) * 10.0 ** rng.integers(-30, 30, n),
        "edges": np.resize(np.array(EDGES), n),
        "int64": rng.integers(-(2**63), 2**63 - 1, n, dtype=np.int64),
        "uint8": rng.integers(0, 255, n, dtype=np.uint8),
        'a "quoted", name': np.arange(n, dtype=np.float64),
    }
    written = write_csv(tmp_path / "ours.csv", columns).read_bytes()
    assert written == _pandas_bytes(tmp_path, columns)
    assert b",," in written or b",\n" in written  # NaN is written as an empty field
    alone = {"x": columns["edges"]}  # a lone empty field is quoted, as the csv module writes it: no blank line
    assert write_csv(tmp_path / "alone.csv", alone).read_bytes() == _pandas_bytes(tmp_path, alone)
    assert b'\n""\n' in (tmp_path / "alone.csv").read_bytes()


def test_other_columns_go_through_pandas(tmp_path):
    columns = {"f32": np.array([0.1, np.nan], np.float32), "flag": np.array([True, False])}
    assert write_csv(tmp_path / "ours.csv", columns).read_bytes() == _pandas_bytes(tmp_path, columns)
    alone = {"f32": columns["f32"]}  # float32's own shortest form, not its float64 value's
    assert write_csv(tmp_path / "f32.csv", alone).read_text() == 'f32\n0.1\n""\n' == _pandas_bytes(tmp_path, alone).decode()
    others = {
        "masked": {"a": np.ma.masked_array([1.0, 2.0], mask=[False, True]), "b": np.zeros(2)},
        "tuple names": {("a", "x"): np.zeros(2), ("b", "y"): np.ones(2)},
        "series": {"a": pd.Series([1.0, 2.0], index=[0, 1]), "b": pd.Series([3.0, 4.0], index=[1, 2])},
        "big-endian": {"a": np.array([0.1, 2.0], dtype=">f8")},
    }
    for name, table in others.items():
        assert write_csv(tmp_path / "o.csv", table).read_bytes() == _pandas_bytes(tmp_path, table), name
    with pytest.raises(ValueError, match="same length"):
        write_csv(tmp_path / "ragged.csv", {"a": np.zeros(2), "b": np.zeros(3)})


def test_the_float_and_integer_columns_are_written_without_pandas(tmp_path):
    code = (
        "import sys, numpy as np\n"
        "from kalcal.io.results import write_csv\n"
        f"write_csv({str(tmp_path / 'x.csv')!r}, {{'a': np.array([0.5, np.nan]), 'n': np.arange(2)}})\n"
        "print('pandas' in sys.modules)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["False"]
    assert (tmp_path / "x.csv").read_text() == "a,n\n0.5,0\n,1\n"
