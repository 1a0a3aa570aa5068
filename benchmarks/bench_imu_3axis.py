"""``kalcal verify imu-3axis`` with the EKF (12 poses: K = 12 updates of 11 states), every statistic included,
against dynamax's ``extended_kalman_filter`` on the same model.

Run: python benchmarks/bench_imu_3axis.py [n]   (default n = 100000). Prints seconds (wall and CPU), the
path that ran (the compiled EKF kernel: its compile or cache load timed apart), the ratio and a profile of
one block, not assertions. dynamax (the ``bench`` extra) runs under jit(vmap), float64, in chunks of 4096 realizations,
its compile timed apart, on measurements drawn by the same truth beforehand (not timed); the ratio is
dynamax's filter alone over kalcal's whole Monte Carlo (simulation, filter, every statistic and the
bound's expectations, then the checks and effect sizes): above 1, kalcal is faster.
"""

from __future__ import annotations

import importlib.util
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

from kalcal.core.nonlinear_run import run_nonlinear_filter
from kalcal.montecarlo.accumulators import ensemble_statistics
from kalcal.montecarlo.engine import block_generator, run_monte_carlo
from kalcal.scenarios import build_scenario
from kalcal.stats.suite import run_checks

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_nonlinear import profile  # noqa: E402  one profile of a block for both nonlinear benchmarks


def main(n: int, chunk: int = 4096) -> None:
    scenario = build_scenario("imu-3axis", None, ["filter.kind=ekf"])
    # planned as kalcal verify plans it (filter.compiled=auto)
    problem = scenario.problem().plan(n)
    loaded = scenario.loaded
    print(f"machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} (1 min) at the start")
    start = time.perf_counter()
    loaded.filter.jacobians  # sympy's derivation once, outside the timing (as a warm run has it)
    # the compiled kernel's printing and numba's compile (or its load from numba's cache), timed apart as
    # dynamax's compile is: asked for by filter.compiled=yes, then found compiled by auto
    forced = build_scenario("imu-3axis", None, ["filter.kind=ekf", "filter.compiled=yes"]).problem()
    if forced.compiled_path[0]:
        forced.block_sums(block_generator(0, 0), 64, "exact")
    setup = time.perf_counter() - start
    compiled, reason = problem.compiled_path
    print(f"kalcal path: {'compiled EKF kernel' if compiled else 'batched numpy (' + reason + ')'}; "
          f"derivation and compile or cache load {setup:.1f} s (apart)")
    start, cpu = time.perf_counter(), time.process_time()
    run = run_monte_carlo(problem, n, 0)
    checks = run_checks(ensemble_statistics(run.sums), problem.info, 0.99)
    effects = problem.effect_sizes(run.sums, 0.99)
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"kalcal blocks ran on: {problem.tally.describe()}")  # the path that ran, not the one asked for
    print(f"kalcal verify imu-3axis, EKF, {loaded.n_updates} poses, N = {n}: {wall:.2f} s ({run.workers} threads, "
          f"{cpu:.2f} s of CPU), peak RSS {rss:.0f} MB; exact checks {[c.name for c in checks if not c.passed]} failed; "
          f"tolerance verdict {effects.verdict()}")
    if importlib.util.find_spec("dynamax") is None:
        print("dynamax comparison: not run (dynamax is not installed: pip install 'kalcal[bench]')")
        return
    compile_s, filter_s, agree, filter_cpu = dynamax_ekf(problem, n, chunk)
    ratio = filter_s / wall
    print(f"dynamax extended_kalman_filter, jit(vmap), float64, chunks of {chunk}: compile {compile_s:.1f} s (apart), "
          f"filter {filter_s:.2f} s ({filter_cpu:.2f} s of CPU) for N = {n}; its posterior means against kalcal's EKF on "
          f"the first chunk, largest difference per realization relative to the largest mean: median {agree[0]:.1e}, "
          f"largest {agree[1]:.1e}")
    print(f"ratio dynamax filter / kalcal Monte Carlo with every statistic: {ratio:.2f} "
          f"({'meets' if ratio >= 10 else 'misses'} the 10x goal); of CPU seconds "
          f"(dynamax's filter {filter_cpu:.2f} s, kalcal's run {cpu:.2f} s): {filter_cpu / cpu:.2f}")
    print(f"load average {os.getloadavg()[0]:.1f} (1 min) at the end")
    if compiled:
        profile(problem, chunk, repeats=5)


def dynamax_ekf(problem, n: int, chunk: int) -> tuple[float, float, tuple[float, float], float]:
    """dynamax's EKF of the pose model (the pose's data as dynamax's inputs): seconds to compile, seconds to
    filter every chunk, its filtered means' largest difference from kalcal's EKF on the first chunk, and
    the CPU seconds of the filter (every thread of this process)."""
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    from dynamax.nonlinear_gaussian_ssm import ParamsNLGSSM, extended_kalman_filter

    loaded = problem.scenario.loaded
    m, data = loaded.filter, loaded.data
    keep = jnp.asarray(np.r_[np.ones(9), 0.0, 0.0])

    def f(x, u):
        return x * keep  # the parameters kept, the next pose's tilts at their prior mean

    def h(x, u):
        return m.h(x[None], u[None])[0]  # the same xmath h, on jax arrays

    # dynamax's prior is of the first measured state: one predict of kalcal's x_0, P_0 (f is linear)
    params = ParamsNLGSSM(
        initial_mean=jnp.asarray(m.x0 * np.asarray(keep)), initial_covariance=jnp.asarray(np.diag(np.asarray(keep)) @ m.p0 @ np.diag(np.asarray(keep)) + m.q),
        dynamics_function=f, dynamics_covariance=jnp.asarray(m.q), emission_function=h, emission_covariance=jnp.asarray(m.r),
    )
    inputs = jnp.asarray(data)
    fields = ["filtered_means", "filtered_covariances"]
    batched = jax.jit(jax.vmap(lambda y: extended_kalman_filter(params, y, inputs=inputs, output_fields=fields)))
    rng = np.random.default_rng(1)
    chunks = [problem._simulate(rng, min(chunk, n - s))[2] for s in range(0, n, chunk)]
    start = time.perf_counter()
    compiled = batched.lower(jnp.asarray(chunks[0])).compile()
    compile_s = time.perf_counter() - start
    first = None
    start, cpu = time.perf_counter(), time.process_time()
    for z in chunks:
        if z.shape[0] != chunks[0].shape[0]:  # the last chunk padded to the compiled shape
            z = np.concatenate([z, np.repeat(z[-1:], chunks[0].shape[0] - z.shape[0], axis=0)])
        out = compiled(jnp.asarray(z))
        out.filtered_means.block_until_ready()
        if first is None:
            first = np.asarray(out.filtered_means)
            assert first.dtype == np.float64, first.dtype
    filter_s, filter_cpu = time.perf_counter() - start, time.process_time() - cpu
    ours = run_nonlinear_filter(m, chunks[0], data=data).x
    scale = np.max(np.abs(ours))
    worst = np.max(np.abs(first - ours), axis=(1, 2)) / scale
    return compile_s, filter_s, (float(np.median(worst)), float(np.max(worst))), filter_cpu


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 100_000)
