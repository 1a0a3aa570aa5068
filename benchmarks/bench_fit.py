"""`kalcal fit accel-gps` of a long log as a ratio to one `kalcal calibrate` of it: one hour at 200 Hz / 5 Hz.

    python benchmarks/bench_fit.py

Each command runs whole, in its own child process (`python -m kalcal ...`: start-up, reading the CSV
logs, the work and the output files), on the log of benchmarks/bench_calibrate.py. Prints the seconds of
`calibrate`, of `fit` with the default free settings and intervals (the goal: at most 5 times
`calibrate`), and of `fit --profile` apart (profile intervals re-maximize the others at each point).
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_calibrate import make_logs  # noqa: E402

GOAL = 5.0


def timed(*args: str) -> float:
    """Seconds of one whole ``kalcal`` command in a child process."""
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "kalcal", *args], check=True, capture_output=True, text=True)
    return time.perf_counter() - start


def main() -> None:
    print("kalcal fit benchmark: 1 hour, 200 Hz accelerometer (720,001 rows), 5 Hz GPS (18,000 fixes), CSV, whole commands",
          flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        paths = make_logs(tmp)
        logs = ["--imu", str(paths["imu.csv"]), "--gps", str(paths["gps.csv"])]
        timed("calibrate", "accel-gps", *logs, "--out", str(tmp / "warm"))  # compiled kernels cached once
        calibrate = timed("calibrate", "accel-gps", *logs, "--out", str(tmp / "cal"))
        print(f"  calibrate                      {calibrate:8.2f} s", flush=True)
        fit = timed("fit", "accel-gps", *logs, "--out", str(tmp / "fit"))
        print(f"  fit (default free, intervals)  {fit:8.2f} s   {fit / calibrate:5.2f} x calibrate (goal <= {GOAL:g} x)",
              flush=True)
        profile = timed("fit", "accel-gps", *logs, "--out", str(tmp / "fit-profile"), "--profile")
        print(f"  fit --profile                  {profile:8.2f} s   {profile / calibrate:5.2f} x calibrate", flush=True)


if __name__ == "__main__":
    main()
