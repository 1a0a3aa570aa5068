"""Calibration of a long log: one hour at 200 Hz (720,001 accelerometer rows, 18,000 fixes).

    python benchmarks/bench_calibrate.py

Prints the time to read the logs (CSV and Parquet), the filter alone, and the whole job (read, filter,
diagnostics, estimates.csv, summary.json, the figure), after start-up; one likelihood evaluation of the
prepared log (O(fixes); the preparation once, O(samples), timed apart) as a ratio to one filter run; the
whole ``kalcal calibrate`` command in a child process, as a user runs it, against the job in this
process (a ratio, with no bound), in wall time and in CPU time (which other work on the machine moves
less); and the job's peak memory against the size of the input, measured
in a child process.
"""

from __future__ import annotations

import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
import kalcal  # noqa: E402
from bench_job import elapsed, machine  # noqa: E402
from kalcal.scenarios.accel_gps.calibration import calibrate_accel_gps, prepare_accel_gps_log  # noqa: E402
from kalcal.io.logs import numeric_columns, read_table  # noqa: E402
from kalcal.scenarios import build_scenario  # noqa: E402

HOURS = 1.0
REPEATS = 2


def job_in_process(scenario, paths: dict[str, Path], tmp: Path) -> tuple[float, float]:
    """The whole calibrate job from the Parquet logs, in this process (warm): (wall, CPU) s."""
    start, cpu = time.perf_counter(), time.process_time()
    kalcal.calibrate(scenario, imu=paths["imu.parquet"], gps=paths["gps.parquet"], out=tmp / "out-again")
    return time.perf_counter() - start, time.process_time() - cpu


def command_cpu(command: list[str]) -> float:
    """CPU seconds (user + system) of one child process: less moved than its wall time by other work on
    the machine."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime


def make_logs(directory: Path) -> dict[str, Path]:
    """An hour of the report's motion, simulated directly (no per-sample Python loop)."""
    rng = np.random.default_rng(0)
    dt, duration = 0.005, 3600.0 * HOURS
    t = np.arange(0.0, duration + dt / 2, dt)
    a = 10 * np.sin(0.1 * t)
    bias = 0.05
    accel = a + bias + 0.02 * rng.standard_normal(t.size)
    fixes = np.arange(0.2, duration + 1e-9, 0.2)
    v = 100 + 100 * (1 - np.cos(0.1 * fixes))
    p = (100 + 100) * fixes - 1000 * np.sin(0.1 * fixes)
    imu = pd.DataFrame({"time": t, "accel": accel})
    gps = pd.DataFrame(
        {
            "time": fixes,
            "position": p + rng.standard_normal(fixes.size),
            "velocity": v + 0.04 * rng.standard_normal(fixes.size),
        }
    )
    paths = {}
    for kind in ("csv", "parquet"):
        paths[f"imu.{kind}"] = directory / f"imu.{kind}"
        paths[f"gps.{kind}"] = directory / f"gps.{kind}"
        if kind == "csv":
            imu.to_csv(paths["imu.csv"], index=False)
            gps.to_csv(paths["gps.csv"], index=False)
        else:
            imu.to_parquet(paths["imu.parquet"])
            gps.to_parquet(paths["gps.parquet"])
    return paths


def peak_memory_mib(imu: Path, gps: Path, out: Path) -> float:
    code = (
        "import kalcal\n"
        f"kalcal.calibrate('accel-gps', imu={str(imu)!r}, gps={str(gps)!r}, out={str(out)!r})\n"
        "print(open('/proc/self/status').read().split('VmHWM:')[1].split()[0])\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return int(result.stdout.split()[-1]) / 1024


def main() -> None:
    scenario = build_scenario("accel-gps", None, [], defaults={"scenario.integration": "trapezoid"})
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        paths = make_logs(tmp)
        imu_frame = read_table(paths["imu.parquet"])
        gps_frame = read_table(paths["gps.parquet"])
        imu = numeric_columns(imu_frame, "imu", ("time", "accel"))
        gps = numeric_columns(gps_frame, "gps", ("time", "position", "velocity"))
        input_mib = (sum(a.nbytes for a in imu.values()) + sum(a.nbytes for a in gps.values())) / 2**20
        print(machine())
        print(f"kalcal calibrate benchmark: {imu['time'].size:,} accelerometer rows, {gps['time'].size:,} fixes "
              f"({input_mib:.1f} MiB as float64)")
        for kind in ("csv", "parquet"):
            start = time.perf_counter()
            read_table(paths[f"imu.{kind}"])
            read_table(paths[f"gps.{kind}"])
            print(f"  read {kind:8s}                      {time.perf_counter() - start:6.2f} s")
        few = slice(0, 2001)  # warm up: the compiled filter is built (or loaded from its cache) once per process
        calibrate_accel_gps(scenario, imu["time"][few], imu["accel"][few], gps["time"][:50], gps["position"][:50], gps["velocity"][:50])
        start = time.perf_counter()
        result = calibrate_accel_gps(scenario, imu["time"], imu["accel"], gps["time"], gps["position"], gps["velocity"], init="first-fix")
        filter_s = time.perf_counter() - start
        print(f"  filter alone                       {filter_s:6.2f} s   bias {result.bias[-1]:.5f} ± {result.std[-1, 2]:.1g} (true 0.05)")
        args = (scenario, imu["time"], imu["accel"], gps["time"], gps["position"], gps["velocity"])
        start = time.perf_counter()
        log = prepare_accel_gps_log(*args, init="first-fix")
        prepare_s = time.perf_counter() - start
        log.loglik()  # warm up
        settings = [{"filter.accel_noise_std": 0.02 * f, "filter.gps_position_std": 1.0 / f} for f in (0.8, 0.9, 1.1, 1.25)]
        start = time.perf_counter()
        for values in settings * 5:
            log.loglik(values)
        loglik_s = (time.perf_counter() - start) / (len(settings) * 5)
        start = time.perf_counter()
        log.loglik({"filter.bias_correlation_time": 30.0, "filter.gps_latency": 0.02})
        moved_s = time.perf_counter() - start
        print(f"  prepare the log once               {prepare_s:6.2f} s   ({prepare_s / filter_s:.2f} x the filter)")
        print(f"  one loglik evaluation              {loglik_s * 1e3:6.1f} ms  ({loglik_s / filter_s:.3f} x the filter)")
        print(f"  ... with tau and latency changed   {moved_s * 1e3:6.1f} ms  ({moved_s / filter_s:.3f} x the filter)")
        jobs = {}
        for kind in ("parquet", "csv"):
            start = time.perf_counter()
            kalcal.calibrate(scenario, imu=paths[f"imu.{kind}"], gps=paths[f"gps.{kind}"], out=tmp / f"out-{kind}")
            jobs[kind] = time.perf_counter() - start
            print(f"  whole job from {kind:8s}           {jobs[kind]:6.2f} s")
        command = [
            sys.executable, "-m", "kalcal", "calibrate", "accel-gps", "--imu", str(paths["imu.parquet"]),
            "--gps", str(paths["gps.parquet"]), "--set", "scenario.integration=trapezoid", "--out", str(tmp / "out-cli"),
        ]
        warm = [job_in_process(scenario, paths, tmp) for _ in range(REPEATS)]
        job_s = min(jobs["parquet"], *(wall for wall, _ in warm))
        job_cpu = min(cpu for _, cpu in warm)
        command_s = min(elapsed(command) for _ in range(REPEATS))
        cpu_s = min(command_cpu(command) for _ in range(REPEATS))
        print(f"  kalcal calibrate command (Parquet) {command_s:6.2f} s   ({command_s / job_s:.2f} x the job in this "
              f"process, {job_s:.2f} s; fastest of {REPEATS})")
        print(f"  ... in CPU time                    {cpu_s:6.2f} s   ({cpu_s / job_cpu:.2f} x the job's {job_cpu:.2f} s)")
        peak = peak_memory_mib(paths["imu.parquet"], paths["gps.parquet"], tmp / "out-peak")
        print(f"  peak memory of the job (Parquet):  {peak:6.0f} MiB (with the interpreter and libraries)")


if __name__ == "__main__":
    main()
