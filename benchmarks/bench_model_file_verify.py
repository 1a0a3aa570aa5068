"""Seed 000 as a model file over its log against the built-in ``kalcal verify accel-gps``: Monte Carlo wall time.

    python benchmarks/bench_model_file_verify.py [-n 40960] [--repeats 2]

Reads the real seed file, ``examples/accel_gps_seed000.toml`` (states position, velocity and
accelerometer bias, Euler steps at 200 Hz, the reading as the known input u through b, a GPS fix of
position and velocity every 40 rows), and writes its log as a user makes it: ``kalcal simulate accel-gps
--seed 0`` laid out by ``examples/seed_logs.py`` (30 s: 6001 rows, the accelerometer column and the fix
columns, NaN between fixes). Then it times, in this one process, warm (each call run once before it is
timed, fastest of the repeats):

* ``kalcal.verify(examples/accel_gps_seed000.toml, n, data=LOG)``: the gains from the log's rows (150
  updates of p = 2), every statistic (checks, the exact analysis, the self-check, the power);
* ``kalcal.verify("accel-gps", n)``: the built-in with its defaults (its exact engine, its own 150 updates
  of position and velocity over 30 s, every statistic) and the long-run study off (``long_run=0``: the
  model file has none), the same n and seed;

and prints both and their ratio, model file over built-in (the issue's bound: 1.5). The built-in with its
default long-run study is printed for scale. Numbers are those of the machine it runs on.
"""

from __future__ import annotations

import argparse
import importlib.util
import tempfile
import time
from pathlib import Path

import kalcal

ROOT = Path(__file__).resolve().parents[1]
SEED000 = ROOT / "examples" / "accel_gps_seed000.toml"


def seed_logs():
    """examples/seed_logs.py as a module (it is a script, not a package)."""
    spec = importlib.util.spec_from_file_location("seed_logs", ROOT / "examples" / "seed_logs.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def write_log(folder: Path) -> Path:
    """Seed 000's simulated logs (``kalcal simulate accel-gps --seed 0``) as the file's [data] table."""
    logs = kalcal.simulate("accel-gps", 0).logs
    log = folder / "seed000.csv"
    seed_logs().accel_gps_table(logs["imu"], logs["gps"]).to_csv(log, index=False, float_format="%.17g")
    return log


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
        log = write_log(Path(tmp))
        mine_result = kalcal.verify(SEED000, 1000, seed=1, data=log)
        builtin_result = kalcal.verify("accel-gps", 1000, seed=1, long_run=0)
        updates = tuple(int(r.statistics.sizes["time"]) for r in (mine_result, builtin_result))
        mine = fastest(lambda: kalcal.verify(SEED000, args.n, seed=1, data=log), args.repeats)
        builtin = fastest(lambda: kalcal.verify("accel-gps", args.n, seed=1, long_run=0), args.repeats)
        with_long = fastest(lambda: kalcal.verify("accel-gps", args.n, seed=1), 1)
    print(f"n = {args.n:,}, updates {updates[0]} (model file) and {updates[1]} (built-in), warm, fastest of {args.repeats}")
    print(f"model file over its log (verify examples/accel_gps_seed000.toml --data LOG): {mine:8.3f} s")
    print(f"built-in accel-gps, its defaults, no long run:                              {builtin:8.3f} s")
    print(f"built-in accel-gps, default long run:                                        {with_long:8.3f} s (for scale)")
    print(f"ratio model file / built-in: {mine / builtin:.2f} (bound 1.5)")

if __name__ == "__main__":
    main()
