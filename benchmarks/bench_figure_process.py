"""The default ``kalcal verify`` with its figure process against drawing from the job's own process.

    python benchmarks/bench_figure_process.py [--repeats 3] [--n 300000]

Runs the command in child processes, alternately with the figure process of
:mod:`kalcal.reporting.drawing_server` and without it (the figures drawn by workers forked from the
job's own process, as a job without a figure process does), and prints for each run and the fastest of
each kind: the wall time, the job's own process's CPU time, the CPU time of the job with all its
processes, ``report_s``, and whether the job's own process imported matplotlib; then the ratio of the
fastest wall times. Say the machine's load (``uptime``) beside the numbers: the figure process gains only
where a core is idle.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CHILD = r"""
import json, resource, sys
from kalcal.reporting import drawing_server
if sys.argv[1] == "off":
    drawing_server.wanted = lambda: False
sys.argv = ["kalcal", "verify", "-n", sys.argv[3], "--out", sys.argv[2]]
from kalcal.cli import main
try:
    main()
except SystemExit as exc:
    assert not exc.code, exc.code
usage = resource.getrusage(resource.RUSAGE_SELF)
print(json.dumps([usage.ru_utime + usage.ru_stime, "matplotlib" in sys.modules]), file=sys.stderr)
"""


def one_run(mode: str, n: int) -> tuple[float, float, float, float, bool]:
    """(wall s, own CPU s, CPU s with all its processes, report_s, matplotlib imported) of one job."""
    env = dict(os.environ)
    env.pop("KALCAL_FIGURE_PROCESSES", None)
    with tempfile.TemporaryDirectory() as tmp:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        done = subprocess.run(
            [sys.executable, "-c", CHILD, mode, f"{tmp}/out", str(n)],
            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, check=True,
        )  # fmt: skip
        wall = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        report_s = json.loads(Path(tmp, "out", "summary.json").read_text())["timing"]["report_s"]
    own, matplotlib = json.loads(done.stderr.strip().splitlines()[-1])
    every = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    return wall, own, every, report_s, matplotlib


def main() -> None:
    """Print the runs, the fastest of each kind and the ratio of their wall times."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--n", type=int, default=300_000)
    args = parser.parse_args()
    runs: dict[str, list] = {"on": [], "off": []}
    for _ in range(args.repeats):
        for mode in runs:
            runs[mode].append(one_run(mode, args.n))
            wall, own, every, report_s, matplotlib = runs[mode][-1]
            print(
                f"figure process {mode:3}: wall {wall:6.2f} s  own CPU {own:6.2f} s  all CPU {every:6.2f} s  "
                f"report_s {report_s:5.2f} s  matplotlib in the job's process: {matplotlib}  "
                f"load {os.getloadavg()[0]:.1f}",
                flush=True,
            )
    best = {mode: [min(run[i] for run in rows) for i in range(4)] for mode, rows in runs.items()}
    for mode, (wall, own, every, report_s) in best.items():
        print(f"fastest, figure process {mode:3}: wall {wall:6.2f} s  own CPU {own:6.2f} s  all CPU {every:6.2f} s  report_s {report_s:5.2f} s")
    print(f"wall time without / with the figure process: {best['off'][0] / best['on'][0]:.2f}x")


if __name__ == "__main__":
    main()
