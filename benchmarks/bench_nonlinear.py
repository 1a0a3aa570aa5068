"""The range-bearing example's EKF pass (K = 100 updates, n realizations) and the cost of each Jacobian method.

Run: python benchmarks/bench_nonlinear.py [n]   (default n = 100000). Prints seconds, not assertions.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import sys
import time
from pathlib import Path

import numpy as np

from kalcal.core.nonlinear import load_nonlinear_model
from kalcal.core.nonlinear_run import run_nonlinear_filter

ROOT = Path(__file__).resolve().parents[1]


def main(n: int) -> None:
    model = load_nonlinear_model(ROOT / "examples" / "range_bearing.py").filter
    rng = np.random.default_rng(0)
    x = model.x0 + rng.standard_normal((n, 4)) * np.sqrt(np.diag(model.p0))
    beacon = np.zeros(2)
    methods = ["sympy", "finite"] + (["jax"] if importlib.util.find_spec("jax") else [])
    for method in methods:
        m = dataclasses.replace(model, jacobian=method)
        start = time.perf_counter()
        m.transition_jacobian(x[:2])
        m.measurement_jacobian(x[:2], beacon)
        setup = time.perf_counter() - start  # derivation (sympy) or tracing and compiling (jax)
        m.transition_jacobian(x)
        m.measurement_jacobian(x, beacon)  # jax compiles again for a new batch size
        times = []
        for _ in range(5):
            start = time.perf_counter()
            m.transition_jacobian(x)
            mid = time.perf_counter()
            m.measurement_jacobian(x, beacon)
            times.append((mid - start, time.perf_counter() - mid))
        f_time, h_time = np.min(times, axis=0)
        print(f"jacobian {method:6s}: setup {setup:.2f} s, F {f_time * 1e3:.2f} ms, H {h_time * 1e3:.2f} ms at n = {n}")
    n_updates = 100
    z = np.broadcast_to(np.array([223.0, 0.46]), (n, n_updates, 2))
    data = np.zeros((n_updates, 2))
    for method in ("ekf", "iekf", "ukf"):
        start = time.perf_counter()
        run_nonlinear_filter(model, z, method=method, data=data, keep=False)
        seconds = time.perf_counter() - start
        print(f"{method:4s} pass: {seconds:.2f} s for K = {n_updates} updates x n = {n}: "
              f"{seconds / (n * n_updates) * 1e9:.0f} ns per update per realization")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 100_000)
