"""The default job as the user pays it: ``kalcal verify`` (what ``make run`` runs), end to end.

    python benchmarks/bench_job.py [--n 300000] [--repeats 2] [--warm-only]

Runs the command in a child process, as a user does, and prints from one run on this machine:

* the machine: CPU model, usable CPUs, BLAS and its kernel (the ratios move with it);
* start-up: ``kalcal --help`` against a bare ``python -c pass`` (printed, with no bound);
* the job's wall time, and its parts from ``summary.json``'s ``timing``: the Monte Carlo
  (``monte_carlo_s``), the long-run study's own Monte Carlo (``long_run_s``), the report (``report_s``),
  the start-up and close of the command around the job (the wall time less ``wall_s``: the interpreter,
  the imports before the job starts, putting the files in place) and everything else (checks, exact
  analysis and power, statistics files);
* the raw cost of the run's random draws: its standard normals drawn with the engine's generator, blocks
  and threads, in this process;
* the ratios: the whole job against its two Monte Carlo runs together (main plus long run; bound 5x)
  and the Monte Carlo against its raw draws.

The first run on a machine compiles the kernels (numba caches them): it is run once with numba's cache
pointed at an empty folder (``NUMBA_CACHE_DIR``), so that it compiles whatever the machine's cache holds,
and reported apart as "first run" (``--warm-only`` leaves it out); the timed runs follow with the cache warm.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from kalcal.montecarlo.engine import block_generator, block_sizes

WORKERS = len(os.sched_getaffinity(0))
KALCAL = [sys.executable, "-m", "kalcal"]


def machine() -> str:
    """The machine the ratios were measured on, in one line: the CPU's model, the CPUs this process may
    use and the BLAS with the kernel it chose. The ratios move with the machine (the all-pairs products
    run at BLAS's peak, the draws do not), so each printout says where it was made."""
    from threadpoolctl import threadpool_info

    model = "unknown CPU"
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    blas = [
        f"{info['internal_api']} {info.get('version') or ''} ({info.get('architecture') or 'kernel unknown'})".replace("  ", " ")
        for info in threadpool_info() if info.get("user_api") == "blas"
    ]  # fmt: skip
    return f"machine: {model}, {WORKERS} CPUs usable, BLAS {', '.join(blas) or 'unknown'}"


def elapsed(command: list[str], env: dict[str, str] | None = None) -> float:
    """Wall time of one child process, s (it must succeed)."""
    start = time.perf_counter()
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    return time.perf_counter() - start


def raw_draws(n: int, normals_per_realization: int, seed: int = 0) -> float:
    """Time to draw exactly the normals of n realizations, block by block, on the engine's threads, s."""
    sizes = block_sizes(n)

    def draw(block: int) -> None:
        block_generator(seed, block).standard_normal(sizes[block] * normals_per_realization)

    start = time.perf_counter()
    with ThreadPoolExecutor(WORKERS) as pool:
        list(pool.map(draw, range(len(sizes))))
    return time.perf_counter() - start


def run_job(n: int, cold: bool = False) -> tuple[float, dict]:
    """``kalcal verify -n n --out DIR``: its wall time (s) and its summary.json; ``cold``: with an empty
    kernel cache, so that every kernel is compiled."""
    with tempfile.TemporaryDirectory() as out, tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache} if cold else None
        wall = elapsed([*KALCAL, "verify", "-n", str(n), "--out", out], env)
        return wall, json.loads((Path(out) / "summary.json").read_text())


def parts(wall: float, summary: dict) -> dict[str, float]:
    """The job's parts, s: wall, start-up (outside the job's own ``wall_s``), Monte Carlo, long run,
    report, everything else, and ``beyond``: all but the two Monte Carlo runs."""
    timing = summary["timing"]
    long_run = timing["long_run_s"]
    report = timing.get("report_s") or 0.0
    monte_carlo = timing["monte_carlo_s"]
    startup = wall - timing["wall_s"]
    return {
        "wall": wall,
        "startup": startup,
        "monte_carlo": monte_carlo,
        "long_run": long_run,
        "report": report,
        "other": timing["wall_s"] - monte_carlo - long_run - report,
        "beyond": wall - monte_carlo - long_run,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=300_000, help="realizations (default: the job's default)")
    parser.add_argument("--repeats", type=int, default=2, help="warm runs; the fastest is shown")
    parser.add_argument("--warm-only", action="store_true", help="leave out the first run with an empty kernel cache")
    args = parser.parse_args()

    bare = min(elapsed([sys.executable, "-c", "pass"]) for _ in range(5))
    help_s = min(elapsed([*KALCAL, "--help"]) for _ in range(5))
    print(machine())
    print(f"start-up ({WORKERS} threads)")
    print(f"  python -c pass:  {bare:7.3f} s")
    print(f"  kalcal --help:   {help_s:7.3f} s   ({help_s - bare:+.3f} s over bare python)")

    first = None if args.warm_only else run_job(args.n, cold=True)
    runs = [run_job(args.n) for _ in range(args.repeats)]
    wall, summary = min(runs, key=lambda run: run[0])
    normals = summary["timing"]["normals_per_realization"]
    draws = min(raw_draws(args.n, normals) for _ in range(3))
    job = parts(wall, summary)

    print(f"\nkalcal verify -n {args.n} (defaults, report included), fastest of {args.repeats} warm runs")
    print(f"  wall time:              {job['wall']:7.3f} s")
    print(f"  start-up and close:     {job['startup']:7.3f} s   (interpreter, imports, files put in place)")
    print(f"  Monte Carlo:            {job['monte_carlo']:7.3f} s")
    print(f"  long-run Monte Carlo:   {job['long_run']:7.3f} s")
    print(f"  report:                 {job['report']:7.3f} s")
    print(f"  everything else:        {job['other']:7.3f} s   (checks, exact analysis and power, statistics files)")
    print(f"  raw draws ({normals} normals/realization): {draws:7.3f} s")
    if first is not None:
        first_parts = parts(*first)
        print(
            f"  first run (empty kernel cache): wall {first_parts['wall']:.3f} s, Monte Carlo "
            f"{first_parts['monte_carlo']:.3f} s; compiling costs {first_parts['wall'] - job['wall']:+.3f} s once"
        )
    both = job["monte_carlo"] + job["long_run"]
    print("\nratios")
    print(f"  whole job / the two Monte Carlo runs ({both:.3f} s):  {job['wall'] / both:5.2f}x   (bound 5x)")
    print(f"  Monte Carlo / raw draws:                             {job['monte_carlo'] / draws:5.2f}x")


if __name__ == "__main__":
    main()
