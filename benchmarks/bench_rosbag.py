"""Reading a long bag: a static IMU topic of 200,000 sensor_msgs/Imu messages (ROS 1).

    python benchmarks/bench_rosbag.py [--n 200000] [--bag FILE]

Writes the bag (with rosbags' writer, as the tests do; or takes ``--bag``), then reads its ``/imu`` topic
with :func:`kalcal.io.rosbag.read_bag` in a child process and prints the messages per second, the
process's peak resident memory above its baseline (the libraries imported first), per message, against
the table's own size (40 float64 columns and the time: 328 B per message) and against what rosbags'
reader alone holds once the bag is open (its index of every message). Printed with no bound: the memory
beyond the columns and rosbags' index is the bound the reader keeps to (a constant, not per message).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import resource, sys, time
import numpy, pandas, rosbags.highlevel  # imported before the baseline
from pathlib import Path
from kalcal.io.rosbag import read_bag
what, path = sys.argv[1], sys.argv[2]
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
start = time.perf_counter()
if what == "index":
    reader = rosbags.highlevel.AnyReader([Path(path)])
    reader.open()
    n = sum(c.msgcount for c in reader.connections)
    size = 0
else:
    frame = read_bag(path, "/imu")
    n, size = len(frame), int(frame.memory_usage().sum())
elapsed = time.perf_counter() - start
print(n, elapsed, (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - base) * 1024, size)
"""


def measure(what: str, bag: Path) -> tuple[int, float, int, int]:
    out = subprocess.run([sys.executable, "-c", CHILD, what, str(bag)], capture_output=True, text=True, check=True,
                         env={"PYTHONPATH": str(ROOT / "src"), "PATH": ""})
    n, elapsed, peak, size = out.stdout.split()
    return int(n), float(elapsed), int(peak), int(size)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--n", type=int, default=200_000)
    parser.add_argument("--bag", type=Path)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        bag = args.bag
        if bag is None:
            sys.path.insert(0, str(ROOT))
            from tests._logfiles import ORIGIN_NS, write_imu_bag

            stamps = ORIGIN_NS + np.arange(args.n, dtype=np.int64) * 2_500_000  # 400 Hz
            accel = np.array([0.05, -0.03, 9.81]) + 0.02 * np.random.default_rng(0).standard_normal((args.n, 3))
            bag = write_imu_bag(Path(tmp) / "static.bag", stamps, accel)
        n, elapsed, peak, size = measure("read", bag)
        _, _, index, _ = measure("index", bag)
        print(f"{bag}: {n} messages read in {elapsed:.2f} s: {n / elapsed:,.0f} messages/s")
        print(f"peak memory above the baseline: {peak / 1e6:.1f} MB = {peak / n:.0f} B per message")
        print(f"  the table's own size:          {size / 1e6:.1f} MB = {size / n:.0f} B per message")
        print(f"  rosbags' reader, bag open:     {index / 1e6:.1f} MB = {index / n:.0f} B per message")
        print(f"  beyond both:                   {(peak - size - index) / 1e6:.1f} MB")


if __name__ == "__main__":
    main()
