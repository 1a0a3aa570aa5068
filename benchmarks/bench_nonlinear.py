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




def bench_verify(n: int) -> None:
    """The EKF Monte Carlo of the range-bearing example, every statistic included (the checks' sums, the
    effect sizes' and the Cramér–Rao bound's), then the checks and effect sizes: wall time and this
    process's peak RSS (run once per N in its own process: ``python bench_nonlinear.py verify N``)."""
    import resource
    import time as _time

    from kalcal.montecarlo.accumulators import ensemble_statistics
    from kalcal.montecarlo.engine import run_monte_carlo
    from kalcal.scenarios import load_code_model
    from kalcal.stats.suite import run_checks

    problem = load_code_model(str(Path(__file__).resolve().parents[1] / "examples" / "range_bearing.py")).problem()
    start = _time.perf_counter()
    run = run_monte_carlo(problem, n, 0)
    checks = run_checks(ensemble_statistics(run.sums), problem.info, 0.99)
    effects = problem.effect_sizes(run.sums, 0.99)
    wall = _time.perf_counter() - start
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"EKF verify, K = 100, N = {n}: {wall:.1f} s ({run.workers} threads), peak RSS {rss:.0f} MB; "
          f"exact checks {[c.name for c in checks if not c.passed]} failed; tolerance verdict "
          f"{'pass' if effects.within_tolerance() else 'fail'}")
    print("dynamax comparison: not run (dynamax is not installed in this environment)")


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "verify":
        bench_verify(int(sys.argv[2]) if len(sys.argv) > 2 else 100_000)
    else:
        main(int(sys.argv[1]) if len(sys.argv) > 1 else 100_000)
