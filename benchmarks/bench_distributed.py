"""Scale-out throughput on local Dask clusters, measured in one run.

    python benchmarks/bench_distributed.py [--n 1000000]

Prints realizations per second of the exact engine (every statistic, the report's scenario) on local
threads and on local Dask clusters of 1 and 2 single-threaded worker processes, the scaling efficiency
(rate with 2 workers / (2 x rate with 1)), the per-core throughput to expect on a cluster, and checks
that every configuration gives the same sums.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
from distributed import Client, LocalCluster

from kalcal.scenarios.accel_gps.settings import AccelGpsScenario
from kalcal.montecarlo.engine import BLOCK_SIZE, run_monte_carlo
from kalcal.scenarios.accel_gps.problem import accel_gps_problem


def timed_run(problem, n, **options):
    start = time.perf_counter()
    run = run_monte_carlo(problem, n, seed=0, **options)
    return time.perf_counter() - start, run.sums


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--n", type=int, default=1_000_000)
    args = parser.parse_args()
    problem = accel_gps_problem(AccelGpsScenario())
    cores = len(os.sched_getaffinity(0))
    print(f"kalcal scale-out benchmark: accel-gps, N = {args.n:,}, block {BLOCK_SIZE}, {cores} cores")
    run_monte_carlo(problem, 2 * BLOCK_SIZE)  # compile
    t_threads, reference = timed_run(problem, args.n)
    print(f"  local threads ({cores}):        {args.n / t_threads:12,.0f} realizations/s")
    rates = {}
    for workers in (1, 2):
        with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
            with Client(cluster) as client:
                run_monte_carlo(problem, 2 * BLOCK_SIZE, client=client)  # compile on the workers
                elapsed, sums = timed_run(problem, args.n, client=client)
        same = all(
            (a is None and b is None) or np.array_equal(a, b)
            for a, b in ((getattr(reference, f), getattr(sums, f)) for f in reference.__dataclass_fields__)
        )
        rates[workers] = args.n / elapsed
        print(f"  Dask, {workers} worker process(es):  {rates[workers]:12,.0f} realizations/s   same sums as threads: {same}")
    print(f"  scaling efficiency 1 -> 2 workers: {rates[2] / (2 * rates[1]):.0%}")
    print(f"  expect about {rates[1]:,.0f} realizations/s per worker core on a cluster of similar cores")


if __name__ == "__main__":
    main()
