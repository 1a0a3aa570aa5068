"""`kalcal fit accel-gps` of a long log as a ratio to one `kalcal calibrate` of it: one hour at 200 Hz / 5 Hz.

    python benchmarks/bench_fit.py               (every part: accel-gps, the model file, the bootstraps)
    python benchmarks/bench_fit.py --model-file  (the model file's part alone)
    python benchmarks/bench_fit.py --bootstrap   (the bootstrap parts alone)

Each command runs whole, in its own child process (`python -m kalcal ...`: start-up, reading the CSV
logs, the work and the output files), on the log of benchmarks/bench_calibrate.py. Prints the seconds of
`calibrate`, of `fit` with the default free settings and intervals (the goal: at most 5 times
`calibrate`), and of `fit --profile` apart (profile intervals re-maximize the others at each point).

Then a model file (:func:`model_file_part`): a local linear trend (level and slope random walks, exact diffuse)
on 10^4 simulated updates, three variances free (``filter.v,filter.w.1,filter.w.2``): the seconds of
``kalcal fit MODEL.toml`` against one ``kalcal calibrate MODEL.toml`` of the same log (goal: within 5x),
whole commands in child processes, each run once untimed first (compiled kernels cached). In-process the
filter and the fit are timed warm too (no start-up): bind the log
(:func:`kalcal.scenarios.model_file.data.bind`) and one ``filter_model``, against ``fit_model_file``.

Then the parametric bootstrap (:func:`bootstrap_part`): ``kalcal.fit(..., bootstrap=200)`` of a 10-minute
scale-bias log at 10 Hz (6000 samples, two settings free) against one fit of it (its intervals and curves),
both in-process and warm, on the threads this process may use (goal: within 100x); and the same for
accel-gps (:func:`bootstrap_accel_gps_part`): a 10-minute simulated log (200 Hz accelerometer, 5 Hz GPS, 3000
fixes), the four default settings free, 200 refits against one fit.
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


MODEL_FILE = """
name = "llt"
phi = [[1.0, 1.0], [0.0, 1.0]]
gamma = [[1.0, 0.0], [0.0, 1.0]]
h = [[1.0, 0.0]]
w = [[0.1, 0.0], [0.0, 0.001]]
v = [[1.0]]
x0 = [0.0, 0.0]
m0 = [[0.0, 0.0], [0.0, 0.0]]
diffuse = ["level", "slope"]
state_names = ["level", "slope"]
[data]
time = "time"
measurements = ["z"]
"""

def model_file_part(updates: int = 10_000, seed: int = 0) -> None:
    """`kalcal fit MODEL.toml` of 10^4 updates, 3 free variances, against one calibrate of it (module docstring)."""
    import numpy as np
    import pandas as pd

    from kalcal.core.timevarying_filter import filter_model
    from kalcal.scenarios.model_file.data import bind
    from kalcal.scenarios.model_file.fit import fit_model_file
    from kalcal.scenarios.model_file.model import load_model_file

    print(f"model file: local linear trend, {updates} updates, free filter.v,filter.w.1,filter.w.2", flush=True)
    rng = np.random.default_rng(seed)
    slope = np.cumsum(rng.normal(scale=np.sqrt(0.004), size=updates))
    level = np.cumsum(slope + rng.normal(scale=np.sqrt(0.05), size=updates))
    z = level + rng.normal(scale=np.sqrt(2.0), size=updates)
    free = "filter.v,filter.w.1,filter.w.2"
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        model, log = tmp / "llt.toml", tmp / "log.csv"
        model.write_text(MODEL_FILE)
        pd.DataFrame({"time": np.arange(updates, dtype=float), "z": z}).to_csv(log, index=False)
        timed("calibrate", str(model), "--data", str(log), "--out", str(tmp / "warm"))  # compiled kernels cached once
        calibrate = timed("calibrate", str(model), "--data", str(log), "--out", str(tmp / "cal"))
        print(f"  {'calibrate':48s} {calibrate:8.2f} s", flush=True)
        timed("fit", str(model), "--data", str(log), "--free", free, "--out", str(tmp / "fit-warm"))
        fit = timed("fit", str(model), "--data", str(log), "--free", free, "--out", str(tmp / "fit"))
        print(f"  {'fit':48s} {fit:8.2f} s   {fit / calibrate:5.2f} x (goal <= {GOAL:g} x)", flush=True)
        scenario = load_model_file(model)
        bound = bind(scenario, log)
        filter_model(bound.filter, bound.z)  # compiled once
        start = time.perf_counter()
        bound = bind(scenario, log)
        filter_model(bound.filter, bound.z)
        once = time.perf_counter() - start
        start = time.perf_counter()
        result = fit_model_file(scenario, log, free=free.split(","))
        search = time.perf_counter() - start
        print(f"  in process, warm: bind + filter_model {once * 1e3:8.1f} ms; fit {search:6.2f} s "
              f"({search / once:6.1f} x: the search, the Hessian and the curves evaluate log L about a hundred times)",
              flush=True)
        print("  estimates: " + ", ".join(f"{k} = {p.value:.4g}" for k, p in result.parameters.items())
              + " (simulated: v 2, w.1 0.05, w.2 0.004)", flush=True)


def bootstrap_part(replicates: int = 200, seed: int = 0) -> None:
    """``kalcal.fit(scale-bias, bootstrap=replicates)`` of a 10-minute log against one fit of it (module docstring)."""
    import numpy as np
    import pandas as pd

    import kalcal

    rng = np.random.default_rng(seed)
    samples = 6000  # 10 minutes at 10 Hz
    sensor = 3.0 * np.sin(np.arange(samples) / 50.0) + 0.1 * rng.standard_normal(samples)
    theta = np.array([1.02, 0.1]) + np.cumsum(1e-3 * rng.standard_normal((samples, 2)), axis=0)
    reference = theta[:, 0] * sensor + theta[:, 1] + 0.05 * rng.standard_normal(samples)
    log = pd.DataFrame({"time": np.arange(samples) / 10.0, "reference": reference, "sensor": sensor})
    _bootstrap_against_one_fit(
        lambda **options: kalcal.fit("scale-bias", data=log, **options), replicates, seed,
        f"scale-bias, 10 minutes at 10 Hz ({samples} samples)",
    )


def bootstrap_accel_gps_part(replicates: int = 200, seed: int = 0) -> None:
    """``kalcal.fit(accel-gps, bootstrap=replicates)`` of a 10-minute log against one fit of it (module docstring)."""
    import kalcal

    sim = kalcal.simulate("accel-gps", seed=seed, settings={"scenario.duration": 600.0})
    imu, gps = sim.logs["imu"], sim.logs["gps"]
    _bootstrap_against_one_fit(
        lambda **options: kalcal.fit("accel-gps", imu=imu, gps=gps, **options), replicates, seed,
        f"accel-gps, 10 minutes ({len(imu)} accelerometer rows, {len(gps)} fixes)",
    )


def _bootstrap_against_one_fit(fit, replicates: int, seed: int, what: str) -> None:
    """Time ``fit()`` once and ``fit(bootstrap=replicates, seed=seed)`` (both warm: a first fit loads the compiled
    kernels) and print their ratio against the goal of 100 x."""
    from kalcal.cpus import usable_cpus

    fit()  # compiled kernels loaded once
    start = time.perf_counter()
    fit()
    once = time.perf_counter() - start
    start = time.perf_counter()
    result = fit(bootstrap=replicates, seed=seed)
    boot = time.perf_counter() - start
    print(f"kalcal fit --bootstrap {replicates}: {what}, {len(result.parameters)} settings free, {usable_cpus()} "
          "thread(s), in-process and warm", flush=True)
    print(f"  fit                    {once:8.2f} s", flush=True)
    print(f"  fit --bootstrap {replicates:<5d}  {boot:8.2f} s   {boot / once:6.1f} x fit (goal <= 100 x); "
          f"{result.bootstrap.failed} refit(s) not converged", flush=True)


if __name__ == "__main__":
    if "--bootstrap" in sys.argv:
        bootstrap_part()
        bootstrap_accel_gps_part()
        sys.exit(0)
    if "--model-file" in sys.argv:
        model_file_part()
        sys.exit(0)
    main()
    model_file_part()
    bootstrap_part()
    bootstrap_accel_gps_part()
