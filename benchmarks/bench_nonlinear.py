"""The range-bearing example's EKF pass (K = 100 updates, n realizations) and the cost of each Jacobian method.

Run: python benchmarks/bench_nonlinear.py [n]   (default n = 100000). Prints seconds, not assertions.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import os
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




def bench_verify(n: int, chunk: int = 4096, with_profile: bool = True) -> None:
    """The EKF Monte Carlo of the range-bearing example, every statistic included (the checks' sums, the
    effect sizes' and the Cramér–Rao bound's), then the checks and effect sizes: wall time and this
    process's peak RSS (run once per N in its own process: ``python bench_nonlinear.py verify N``).

    Then, where dynamax is installed (the ``bench`` extra), the same model's filter by dynamax's
    ``extended_kalman_filter`` under jit(vmap), float64, on the same measurements, in chunks of ``chunk``
    realizations (its vmap returns every filtered mean and covariance: n K (d + d^2) floats, 16 GB at
    N = 10^5 otherwise); its compile is timed apart (one chunk's shape, compiled once). The ratio printed is
    dynamax's filter alone (no statistic, its measurements drawn beforehand and not timed) over kalcal's whole
    run (simulation, filter and every statistic), the compiled kernel's compile (or cache load) timed apart
    as dynamax's is: above 1, kalcal is faster. Where it is under 10, a profile of one block (the draws,
    the compiled kernel, the pair sums, in CPU seconds) says where the time goes.
    """
    import resource
    import time as _time

    from kalcal.montecarlo.accumulators import ensemble_statistics
    from kalcal.montecarlo.engine import run_monte_carlo
    from kalcal.scenarios import load_code_model
    from kalcal.stats.suite import run_checks

    from kalcal.montecarlo.engine import block_generator

    # planned as kalcal verify plans it: filter.compiled=auto compiles for a run of n K >= 10^7
    problem = load_code_model(str(ROOT / "examples" / "range_bearing.py")).problem().plan(n)
    # the machine's load beside every timing: a loaded machine's wall times and ratios are not an idle one's
    print(f"machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} (1 min) at the start")
    compiled, reason = problem.compiled_path
    # the compiled kernel's printing and numba's compile (or its load from numba's cache), timed apart as
    # dynamax's compile is
    start = _time.perf_counter()
    problem.block_sums(block_generator(0, 0), 64, "exact")
    setup = _time.perf_counter() - start
    # the path that ran (the tally of blocks by path), not the one asked for: a kernel that stops at every
    # block would otherwise be timed as the numpy path under the kernel's name
    print(f"kalcal path asked: {'compiled EKF kernel' if compiled else 'batched numpy (' + reason + ')'}; "
          f"first block ran on: {problem.tally.describe()}; compile or cache load {setup:.1f} s (apart)")

    def kalcal_run():
        run = run_monte_carlo(problem, n, 0)
        checks = run_checks(ensemble_statistics(run.sums), problem.info, 0.99)
        return run, checks, problem.effect_sizes(run.sums, 0.99)

    start, cpu = _time.perf_counter(), _time.process_time()
    run, checks, effects = kalcal_run()
    wall, cpu = _time.perf_counter() - start, _time.process_time() - cpu
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"kalcal blocks ran on (setup block included): {problem.tally.describe()}")
    print(f"kalcal EKF verify, K = 100, N = {n}: {wall:.2f} s ({run.workers} threads, {cpu:.2f} s of CPU), "
          f"peak RSS {rss:.0f} MB; exact checks {[c.name for c in checks if not c.passed]} failed; tolerance "
          f"verdict {effects.verdict()}")
    if importlib.util.find_spec("dynamax") is None:
        print("dynamax comparison: not run (dynamax is not installed: pip install 'kalcal[bench]')")
        return
    compile_s, filter_s, agree, filter_cpu = _dynamax_ekf(problem, n, chunk)
    ratio = filter_s / wall
    print(f"dynamax extended_kalman_filter, jit(vmap), float64, chunks of {chunk}: compile {compile_s:.1f} s "
          f"(apart), filter {filter_s:.1f} s ({filter_cpu:.1f} s of CPU) for N = {n}; its posterior means against kalcal's EKF on the first "
          f"chunk, largest difference per realization relative to the largest mean: median {agree[0]:.1e}, "
          f"largest {agree[1]:.1e}")
    print(f"ratio dynamax filter / kalcal Monte Carlo with every statistic: {ratio:.2f} "
          f"({'meets' if ratio >= 10 else 'misses'} the 10x goal); of CPU seconds "
          f"(dynamax's filter {filter_cpu:.1f} s, kalcal's run {cpu:.2f} s): {filter_cpu / cpu:.2f}")
    print(f"load average {os.getloadavg()[0]:.1f} (1 min) at the end")
    if ratio < 10 and with_profile:
        profile(problem, chunk)


def bench_paths(chunk: int = 4096) -> None:
    """One block of the range-bearing example (K = 100) with every statistic on each path, CPU seconds of
    one thread with BLAS on one thread (as the engine runs a block), best of 5 (compiled) and of 2 (numpy):
    the saving per realization-update that ``COMPILE_WORTH`` weighs against a compile
    (``python bench_nonlinear.py paths``)."""
    import time as _time

    from kalcal.montecarlo.engine import block_generator, single_threaded_blas
    from kalcal.scenarios import load_code_model

    print(f"machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} (1 min) at the start")
    example = str(ROOT / "examples" / "range_bearing.py")
    problems = {mode: load_code_model(example, [f"filter.compiled={mode}"]).problem() for mode in ("yes", "no")}
    problems["yes"].block_sums(block_generator(0, 0), 64, "exact")  # the compile or cache load, apart
    k = problems["yes"].scenario.n_updates
    per = {}
    with single_threaded_blas():
        for mode, repeats in (("yes", 5), ("no", 2)):
            best = np.inf
            for _ in range(repeats):
                start = _time.thread_time()
                problems[mode].block_sums(block_generator(0, 1), chunk, "exact")
                best = min(best, _time.thread_time() - start)
            per[mode] = best / (chunk * k)
            print(f"filter.compiled={mode}: one block of {chunk}, K = {k}: {best:.3f} s, "
                  f"{per[mode] * 1e9:.0f} ns per realization-update; ran on {problems[mode].tally.describe()}")
    print(f"saved per realization-update {(per['no'] - per['yes']) * 1e6:.2f} us: a 60 s compile repaid at "
          f"{60.0 / (per['no'] - per['yes']):.2g} realization-updates; load average {os.getloadavg()[0]:.1f} at the end")


def profile(problem, chunk: int, repeats: int = 3) -> None:
    """Print where one block's CPU time goes (cProfile does not see into compiled code): the draws, the compiled kernel (truth, EKF, every sum), the pair
    sums after it, each as CPU seconds of this thread, best of ``repeats``, the whole block with BLAS on one
    thread as the engine runs it (:func:`kalcal.montecarlo.engine.single_threaded_blas`). The state and
    measurement sizes are the problem's truth's; bench_imu_3axis.py prints its profile with it too."""
    from kalcal.montecarlo.accumulators import ResidualProducts
    from kalcal.montecarlo.engine import block_generator, single_threaded_blas

    t = problem.scenario.loaded.truth
    k, d, p = problem.scenario.n_updates, t.state_dim, t.measurement_dim
    drawn = (problem.normals_per_realization("exact") - d) // k  # each update's normals, as the block draws them
    best = {}
    # the whole profiled block with BLAS on one thread, as the engine runs each block (block_task): the pair
    # sums inside block_sums would otherwise run on BLAS's threads, and their waits for a loaded core count
    # as this thread's time and land in the kernel's share
    with single_threaded_blas():
        for _ in range(repeats):
            rng = block_generator(0, 1)
            start = time.thread_time()
            rng.standard_normal((chunk, d))
            rng.standard_normal((k, chunk, drawn))
            draws = time.thread_time() - start
            start = time.thread_time()
            problem.block_sums(block_generator(0, 1), chunk, "exact")
            block = time.thread_time() - start
            stacked = np.ascontiguousarray(np.random.default_rng(0).standard_normal((k * p, chunk)))
            start = time.thread_time()
            ResidualProducts.upper(stacked)
            pairs = time.thread_time() - start
            for name, value in (("draws", draws), ("block", block), ("pairs", pairs)):
                best[name] = min(best.get(name, np.inf), value)
    kernel = best["block"] - best["draws"] - best["pairs"]
    per = chunk * k
    print(f"profile of one block of {chunk} realizations, K = {k} (CPU seconds of one thread, best of {repeats}): "
          f"block {best['block']:.4f} s = draws {best['draws']:.4f} s + compiled kernel {kernel:.4f} s "
          f"({kernel / per * 1e9:.0f} ns per update per realization) + pair sums (syrk) {best['pairs']:.4f} s")


def _dynamax_ekf(problem, n: int, chunk: int) -> tuple[float, float, tuple[float, float], float]:
    """dynamax's EKF of the problem's filter model on n realizations drawn by the problem's truth: seconds
    to compile, seconds to filter every chunk (measurements drawn beforehand, outside the timing), the
    median and largest relative difference of its filtered means from kalcal's EKF on the first chunk, and
    the CPU seconds of the filtering (every thread of the process)."""
    import time as _time

    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    from dynamax.nonlinear_gaussian_ssm import ParamsNLGSSM, extended_kalman_filter

    from kalcal.core.nonlinear_run import run_nonlinear_filter

    m = problem.scenario.loaded.filter
    beacon = jnp.asarray(problem.scenario.loaded.data, dtype=jnp.float64)
    dt = float(m.dt)

    def f(x):
        return jnp.array([x[0] + dt * x[2], x[1] + dt * x[3], x[2], x[3]])

    def h(x):
        dx, dy = x[0] - beacon[0], x[1] - beacon[1]
        return jnp.array([jnp.hypot(dx, dy), jnp.arctan2(dy, dx)])

    # dynamax's prior is of the first measured state; kalcal's of x_0, one step before it: predicted once
    # here (f is linear, so exactly)
    big_f = np.asarray(m.transition_jacobian(np.asarray(m.x0)[None])[0])
    params = ParamsNLGSSM(
        initial_mean=jnp.asarray(big_f @ m.x0), initial_covariance=jnp.asarray(big_f @ m.p0 @ big_f.T + m.q),
        dynamics_function=f, dynamics_covariance=jnp.asarray(m.q), emission_function=h,
        emission_covariance=jnp.asarray(m.r),
    )
    fields = ["filtered_means", "filtered_covariances"]
    batched = jax.jit(jax.vmap(lambda y: extended_kalman_filter(params, y, output_fields=fields)))
    rng = np.random.default_rng(1)
    chunks = [problem._simulate(rng, min(chunk, n - s))[2] for s in range(0, n, chunk)]
    start = _time.perf_counter()
    compiled = batched.lower(jnp.asarray(chunks[0])).compile()
    compile_s = _time.perf_counter() - start
    first = None
    start, cpu = _time.perf_counter(), _time.process_time()
    for z in chunks:
        if z.shape[0] != chunks[0].shape[0]:  # the last chunk padded to the compiled shape
            z = np.concatenate([z, np.repeat(z[-1:], chunks[0].shape[0] - z.shape[0], axis=0)])
        out = compiled(jnp.asarray(z))
        out.filtered_means.block_until_ready()
        if first is None:
            first = np.asarray(out.filtered_means)
            assert first.dtype == np.float64, first.dtype
    filter_s, filter_cpu = _time.perf_counter() - start, _time.process_time() - cpu
    ours = run_nonlinear_filter(m, chunks[0], data=problem.scenario.loaded.data[None].repeat(chunks[0].shape[1], 0)).x
    scale = np.max(np.abs(ours))
    worst = np.max(np.abs(first - ours), axis=(1, 2)) / scale  # per realization, over its updates and states
    return compile_s, filter_s, (float(np.median(worst)), float(np.max(worst))), filter_cpu


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "paths":
        bench_paths()
    elif len(sys.argv) > 1 and sys.argv[1] == "verify":
        bench_verify(int(sys.argv[2]) if len(sys.argv) > 2 else 100_000)
    else:
        main(int(sys.argv[1]) if len(sys.argv) > 1 else 100_000)
