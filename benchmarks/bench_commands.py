"""Each command as the user pays it: its wall time against the same job run warm in one process.

    python benchmarks/bench_commands.py [--repeats 2]

Makes its inputs in a temporary folder (``kalcal simulate``'s accel-gps and scale-bias logs at their
defaults, a static accelerometer log of 2^15 samples at 100 Hz, a 20,000-realization verify run without
the long-run study), then prints, measured in one run on this machine, for each command:

* the command: ``python -m kalcal ...`` in a child process, fastest of the repeats, the compiled kernels'
  cache warm (every command but ``report`` is run once before it is timed; the verify run that report
  redraws warmed its kernels);
* the same job through the Python API in this process, warm (the call repeated after a first one, so
  that its imports, kernel loads and matplotlib are paid already; its figures are drawn here);
* their ratio, command over job: how much longer the user waits than the work takes (the interpreter,
  the imports, the kernels' loading).

``python -c pass`` is printed for scale. The commands write into fresh folders each time, but for
``report``, which redraws the verify run's own page and figures in its folder.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

import kalcal

KALCAL = [sys.executable, "-m", "kalcal"]


def command_wall(args: list[str], repeats: int) -> float:
    """The fastest wall time of ``kalcal args`` (``{out}`` in them replaced by a fresh folder each time), s."""
    best = float("inf")
    for _ in range(repeats):
        with tempfile.TemporaryDirectory() as out:
            command = [*KALCAL, *(a.replace("{out}", str(Path(out) / "run")) for a in args)]
            start = time.perf_counter()
            subprocess.run(command, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            best = min(best, time.perf_counter() - start)
    return best


def api_wall(job: Callable[[Path], object], repeats: int) -> float:
    """The fastest wall time of ``job(out)`` in this process after a first, untimed call, s."""
    with tempfile.TemporaryDirectory() as out:
        job(Path(out) / "first")
        best = float("inf")
        for i in range(repeats):
            start = time.perf_counter()
            job(Path(out) / f"run{i}")
            best = min(best, time.perf_counter() - start)
    return best


def static_log(path: Path) -> Path:
    """A static accelerometer log: white noise of 0.02 m/s^2 at 100 Hz about 0.05 m/s^2 (CSV)."""
    accel = np.random.default_rng(0).normal(0.05, 0.02, 2**15)
    path.write_text("time,accel\n" + "\n".join(f"{i / 100.0!r},{a!r}" for i, a in enumerate(accel.tolist())) + "\n")
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=2)
    repeats = parser.parse_args().repeats
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        accel, sb = tmp / "accel", tmp / "sb"
        subprocess.run([*KALCAL, "simulate", "accel-gps", "--out", str(accel)], check=True, capture_output=True)
        subprocess.run([*KALCAL, "simulate", "scale-bias", "--out", str(sb)], check=True, capture_output=True)
        static = static_log(tmp / "static.csv")
        run = tmp / "verified"
        kalcal.verify(n=20_000, long_run=0, out=run, report=True)
        imu, gps, data = str(accel / "imu.csv"), str(accel / "gps.csv"), str(sb / "data.csv")
        jobs: list[tuple[str, list[str], Callable[[Path], object]]] = [
            ("simulate accel-gps", ["simulate", "accel-gps", "--out", "{out}"],
             lambda out: kalcal.simulate("accel-gps", out=out)),
            ("calibrate accel-gps", ["calibrate", "accel-gps", "--imu", imu, "--gps", gps, "--out", "{out}"],
             lambda out: kalcal.calibrate("accel-gps", imu=imu, gps=gps, out=out)),
            ("fit accel-gps", ["fit", "accel-gps", "--imu", imu, "--gps", gps, "--out", "{out}"],
             lambda out: kalcal.fit("accel-gps", imu=imu, gps=gps, out=out)),
            ("calibrate scale-bias", ["calibrate", "scale-bias", "--data", data, "--out", "{out}"],
             lambda out: kalcal.calibrate("scale-bias", data=data, out=out)),
            ("fit scale-bias", ["fit", "scale-bias", "--data", data, "--out", "{out}"],
             lambda out: kalcal.fit("scale-bias", data=data, out=out)),
            ("noise", ["noise", "--imu", str(static), "--out", "{out}"], lambda out: kalcal.noise(str(static), out=out)),
            ("analyze", ["analyze", "--out", "{out}"], lambda out: kalcal.analyze(out=out)),
            ("verify -n 20000 --long-run 0", ["verify", "-n", "20000", "--long-run", "0", "--out", "{out}"],
             lambda out: kalcal.verify(n=20_000, long_run=0, out=out, report=True)),
            ("report DIR (that verify's)", ["report", str(run)], lambda out: kalcal.report(run)),
        ]  # fmt: skip
        for _, args, _job in jobs:  # the kernels cached and the modules' bytecode compiled, once
            if args[0] != "report":
                command_wall(args, 1)
        bare = min(_elapsed([sys.executable, "-c", "pass"]) for _ in range(3))
        print(f"kalcal commands as the user pays them (fastest of {repeats}); python -c pass: {bare:.3f} s")
        print(f"  {'command':32s} {'command':>8s} {'job, warm':>10s} {'ratio':>6s}")
        for name, args, job in jobs:
            wall = command_wall(args, repeats)
            warm = api_wall(job, repeats)
            print(f"  {name:32s} {wall:7.2f}s {warm:9.2f}s {wall / warm:5.2f}x", flush=True)


def _elapsed(command: list[str]) -> float:
    start = time.perf_counter()
    subprocess.run(command, check=True)
    return time.perf_counter() - start


if __name__ == "__main__":
    main()
