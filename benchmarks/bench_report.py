"""The report alone: ``render_report`` of a verify run, its wall and CPU time.

    python benchmarks/bench_report.py [DIR] [--repeats 3]

DIR is a ``kalcal verify`` output folder (without one, a default run is made with ``--no-report`` into
a temporary folder). Prints the fastest of the repeats of ``render_report(DIR)`` in this process: reading
the statistics files, redrawing the realization shown, drawing every figure one after another and
writing the page.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import matplotlib

import kalcal.reporting.render as report


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", nargs="?", type=Path, help="a kalcal verify output folder (default: a new default run)")
    parser.add_argument("--repeats", type=int, default=3, help="the fastest of this many is shown")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as scratch:
        run = args.run
        if run is None:
            run = Path(scratch) / "run"
            subprocess.run([sys.executable, "-m", "kalcal", "verify", "--no-report", "--out", str(run)], check=True, stdout=subprocess.DEVNULL)
        walls, cpus = [], []
        for _ in range(args.repeats):
            wall, cpu = time.perf_counter(), time.process_time()
            report.render_report(run)
            walls.append(time.perf_counter() - wall)
            cpus.append(time.process_time() - cpu)
        print(f"kalcal report benchmark: matplotlib {matplotlib.__version__}")
        print(f"render_report, fastest of {args.repeats}: {min(walls):.3f} s wall, {min(cpus):.3f} s CPU")


if __name__ == "__main__":
    main()
