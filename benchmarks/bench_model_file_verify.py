"""Seed 000 as a model file over its log against the built-in ``kalcal verify accel-gps``: Monte Carlo wall time.

    python benchmarks/bench_model_file_verify.py [-n 40960] [--repeats 2]

Writes, in a temporary folder, the accelerometer-and-GPS model as a model file (states position, velocity
and accelerometer bias, Euler steps at 200 Hz, the accelerometer reading as the known input u through b,
a GPS position fix every 40 rows) and its log (30 s: 6001 rows, the accelerometer column and the fix
column, NaN between fixes), then times, in this one process, warm (each call run once before it is
timed, fastest of the repeats):

* ``kalcal.verify(MODEL.toml, n, data=LOG)``: the gains from the log's rows (150 updates), every statistic;
* ``kalcal.verify("accel-gps", n)``, the default engine, with the long-run study off (``long_run=0``),
  the same 150 updates and statistics (the model file has no long run);

and prints both and their ratio, model file over built-in (the issue's bound: 1.5). The built-in with its
default long-run study is printed for scale. Numbers are those of the machine it runs on.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

import kalcal

T = 1.0 / 200.0
MODEL = f"""
name = "accel-gps-seed000"
sample_period = {T!r}
phi   = [[1.0, {T!r}, 0.0], [0.0, 1.0, {-T!r}], [0.0, 0.0, 1.0]]
b     = [[0.0], [{T!r}], [0.0]]
gamma = [[0.0], [{T!r}], [0.0]]
h     = [[1.0, 0.0, 0.0]]
w     = [[0.0016]]
v     = [[4.0]]
x0    = [0.0, 0.0, 0.0]
m0    = [[4.0, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 0.01]]
state_names = ["position", "velocity", "accel_bias"]
state_units = ["m", "m/s", "m/s^2"]
[data]
time = "time"
measurements = ["gps"]
inputs = ["accel"]
"""


def write_inputs(folder: Path) -> tuple[Path, Path]:
    """The model file and its 30 s log (6001 rows at 200 Hz, a fix every 40 rows from row 40)."""
    rows = 6001
    gps = np.full(rows, np.nan)
    gps[40::40] = 0.0  # which rows are fixes is all the verification reads of this column
    accel = np.random.default_rng(0).normal(0.0, 0.5, rows)
    log = folder / "log.csv"
    pd.DataFrame({"time": np.arange(rows) * T, "accel": accel, "gps": gps}).to_csv(log, index=False)
    model = folder / "seed000.toml"
    model.write_text(MODEL)
    return model, log


def fastest(job, repeats: int) -> float:
    job()  # warm: imports, kernels
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        job()
        best = min(best, time.perf_counter() - start)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-n", type=int, default=40960)
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        model, log = write_inputs(Path(tmp))
        updates = kalcal.verify(model, 100, data=log).raw_summary["final"]
        del updates
        mine = fastest(lambda: kalcal.verify(model, args.n, seed=1, data=log), args.repeats)
        builtin = fastest(lambda: kalcal.verify("accel-gps", args.n, seed=1, long_run=0), args.repeats)
        with_long = fastest(lambda: kalcal.verify("accel-gps", args.n, seed=1), 1)
    print(f"n = {args.n:,}, 150 updates, warm, fastest of {args.repeats}")
    print(f"model file over its log (verify --data): {mine:8.3f} s")
    print(f"built-in accel-gps, no long run:          {builtin:8.3f} s")
    print(f"built-in accel-gps, default long run:     {with_long:8.3f} s (for scale)")
    print(f"ratio model file / built-in: {mine / builtin:.2f} (bound 1.5)")


if __name__ == "__main__":
    main()
