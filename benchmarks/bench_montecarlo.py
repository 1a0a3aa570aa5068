"""Monte Carlo throughput, as ratios measured in one run on this machine.

    python benchmarks/bench_montecarlo.py [--n 300000] [--quick]

Prints, for the accelerometer/GPS scenario of the source report (3 states, 150 GPS updates, 40
accelerometer samples between them):

* the exact engine with every statistic against the raw cost of drawing its standard normals with the
  same generator, blocks and threads;
* the sampled engine (every 200 Hz sample, its compiled kernel) against the raw cost of its own draws, and
  the numpy sampler it replaces (``sample_accel_gps_errors``, then the filter kernel) against the same;
* the compiled block path against the numpy reference path on the same block, and the pair sums of
  one block as the engine sums them (float64 syrk) against a float32 ssyrk of the same innovations;
* one block's parts on one thread: numpy's draws of its normals, the kernel's own draws of the same
  values, the compiled block with and without the pairs, and the pair sums alone;
* the Monte Carlo in a fresh process, as the CLI pays it: numba's one-time loading (timed apart as a first
  run of 100 realizations), the first blocks and the later ones (from the progress callback's times),
  against the same run warm in this process;
* the exact engine with BLAS free to use every core inside the blocks, against the engine's limit of one;
* realizations per second of kalcal against FilterPy (and simdkalman, and dynamax when installed) run
  in this process on the same workload;
* peak memory of a whole verify run at N = 3 x 10^5 and 3 x 10^6 (in a child process).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import os
import resource
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from scipy.linalg.blas import dsyrk, ssyrk

from kalcal.scenarios.accel_gps.settings import AccelGpsScenario
from kalcal.montecarlo import engine
from kalcal.montecarlo.accumulators import MomentSums, ResidualProducts
from kalcal.montecarlo.engine import BLOCK_SIZE, block_generator, block_sizes, run_monte_carlo
from kalcal.scenarios.accel_gps.problem import accel_gps_problem

WORKERS = len(os.sched_getaffinity(0))


def best_of(repeats, function, *args, **kwargs) -> float:
    """The fastest of ``repeats`` timings, s."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function(*args, **kwargs)
        times.append(time.perf_counter() - start)
    return min(times)


def wall_and_cpu(repeats, function) -> tuple[float, float]:
    """The fastest wall time and the fastest CPU time of this process (every thread) of ``repeats`` calls, s."""
    wall = cpu = float("inf")
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        function()
        wall, cpu = min(wall, time.perf_counter() - start), min(cpu, time.process_time() - start_cpu)
    return wall, cpu


def alternating(repeats, *functions) -> list[float]:
    """The fastest thread-CPU time (s) of each function over ``repeats`` rounds that run them in turn, so that
    a change in the machine's load falls on all of them alike."""
    best = [float("inf")] * len(functions)
    for _ in range(repeats):
        for i, function in enumerate(functions):
            start = time.thread_time()
            function()
            best[i] = min(best[i], time.thread_time() - start)
    return best


def raw_draws(n: int, normals_per_realization: int, seed: int = 0) -> None:
    """Draw exactly the normals of n realizations, block by block, on the engine's threads."""
    sizes = block_sizes(n)

    def draw(block: int) -> None:
        block_generator(seed, block).standard_normal(sizes[block] * normals_per_realization)

    with ThreadPoolExecutor(WORKERS) as pool:
        list(pool.map(draw, range(len(sizes))))


def block_parts(problem, no_pairs, stacked: np.ndarray, normals: int) -> list[float]:
    """Thread CPU times (s) of one block's parts: numpy's draws of its normals, the exact kernel's own
    draws alone, the compiled block with and without the pairs, and the pair sums alone."""
    from kalcal.montecarlo.kernels import standard_normals

    steps = problem.truth.n_updates
    step = np.empty(((normals - (problem.truth.x0_factor.shape[1] + problem.truth.shares_boundary)) // steps, BLOCK_SIZE))

    def kernel_draws() -> None:
        rng = block_generator(0, 0)
        for _ in range(steps):
            standard_normals(rng, step)

    kernel_draws()
    return alternating(
        9,
        lambda: block_generator(0, 0).standard_normal(BLOCK_SIZE * normals),
        kernel_draws,
        lambda: problem.block_sums(block_generator(0, 0), BLOCK_SIZE, "exact"),
        lambda: no_pairs.block_sums(block_generator(0, 0), BLOCK_SIZE, "exact"),
        lambda: ResidualProducts.upper(stacked),
    )


def blas_free_run(problem, n: int) -> float:
    """The fastest of two exact runs with the BLAS limit lifted (every core to BLAS inside each block), s.

    Only for timing: with BLAS threads inside the blocks the pair sums' bits may depend on their count.
    """
    limit = engine.single_threaded_blas
    engine.single_threaded_blas = contextlib.nullcontext
    try:
        return best_of(2, lambda: run_monte_carlo(problem, n, seed=0))
    finally:
        engine.single_threaded_blas = limit


def filterpy_rate(problem, realizations: int, per_sample: bool) -> float:
    """Realizations per second of FilterPy's KalmanFilter on the report's filter (one at a time)."""
    from filterpy.kalman import KalmanFilter

    model = problem.filter_model
    _, measurements = problem.sample(np.random.default_rng(1), realizations, "exact")
    steps = model.steps_per_update if per_sample else 1
    phi = model.phi if per_sample else problem.schedule.phi_interval
    q = model.gamma @ model.w @ model.gamma.T if per_sample else problem.schedule.q_interval
    start = time.perf_counter()
    for i in range(realizations):
        kf = KalmanFilter(dim_x=3, dim_z=2)
        kf.F, kf.Q, kf.H, kf.R, kf.P, kf.x = phi, q, model.h, model.v, model.m0.copy(), model.x0.copy()
        for k in range(measurements.shape[1]):
            for _ in range(steps):
                kf.predict()
            kf.update(measurements[i, k])
    return realizations / (time.perf_counter() - start)


def simdkalman_rate(problem, realizations: int) -> float | None:
    """Realizations per second of simdkalman (vectorized over series) on the update-rate model."""
    try:
        import simdkalman
    except ImportError:
        return None
    model = problem.filter_model
    _, measurements = problem.sample(np.random.default_rng(2), realizations, "exact")
    kf = simdkalman.KalmanFilter(
        state_transition=problem.schedule.phi_interval,
        process_noise=problem.schedule.q_interval,
        observation_model=model.h,
        observation_noise=model.v,
    )
    # simdkalman's prior is at the first observation; propagate the report's prior one interval first.
    mean = problem.schedule.phi_interval @ model.x0
    cov = problem.schedule.phi_interval @ model.m0 @ problem.schedule.phi_interval.T + problem.schedule.q_interval
    start = time.perf_counter()
    kf.compute(measurements, 0, initial_value=mean, initial_covariance=cov, filtered=True, smoothed=False)
    return realizations / (time.perf_counter() - start)


def dynamax_rate(problem, realizations: int) -> float | None:
    """Realizations per second of dynamax (jit + vmap on the CPU), when it is installed."""
    try:
        import jax
        import jax.numpy as jnp
        from dynamax.linear_gaussian_ssm import LinearGaussianSSM
        from dynamax.linear_gaussian_ssm.inference import lgssm_filter
    except ImportError:
        return None
    model = problem.filter_model
    _, measurements = problem.sample(np.random.default_rng(3), realizations, "exact")
    ssm = LinearGaussianSSM(state_dim=3, emission_dim=2)
    phi, q = problem.schedule.phi_interval, problem.schedule.q_interval
    params, _ = ssm.initialize(
        initial_mean=jnp.asarray(phi @ model.x0),
        initial_covariance=jnp.asarray(phi @ model.m0 @ phi.T + q),
        dynamics_weights=jnp.asarray(phi),
        dynamics_covariance=jnp.asarray(q),
        emission_weights=jnp.asarray(model.h),
        emission_covariance=jnp.asarray(model.v),
    )
    run = jax.jit(jax.vmap(lambda ys: lgssm_filter(params, ys).filtered_means))
    run(jnp.asarray(measurements[:2])).block_until_ready()
    start = time.perf_counter()
    run(jnp.asarray(measurements)).block_until_ready()
    return realizations / (time.perf_counter() - start)


FRESH = """
import json, sys, time
start = time.perf_counter()
from kalcal.scenarios.accel_gps.settings import AccelGpsScenario
from kalcal.montecarlo.engine import run_monte_carlo
from kalcal.scenarios.accel_gps.problem import accel_gps_problem
imported = time.perf_counter() - start
setup = 0.0
problem = accel_gps_problem(AccelGpsScenario())
if sys.argv[2] == "setup-first":  # numba's one-time loading, timed apart (the CLI pays it in the first block)
    start = time.perf_counter()
    run_monte_carlo(problem, 100, 1)
    setup = time.perf_counter() - start
marks = []
run = run_monte_carlo(problem, int(sys.argv[1]), 0, progress=lambda done, total: marks.append((done, time.perf_counter())))
print(json.dumps({"imported": imported, "setup": setup, "wall": run.wall_s, "marks": marks}))
"""


def fresh_process(n: int, mode: str) -> dict:
    """One Monte Carlo of n realizations in a new interpreter (numba's cache warm), with its progress times."""
    result = subprocess.run([sys.executable, "-c", FRESH, str(n), mode], capture_output=True, text=True, check=True)
    return json.loads(result.stdout.strip().splitlines()[-1])


def block_times(marks: list) -> tuple[float, float]:
    """(time to the first finished block, median time per block per thread after it), s, from progress marks."""
    start = marks[0][1]
    finished = [t for done, t in marks[1:]]
    first = finished[0] - start
    later = np.diff(finished[WORKERS:]) * WORKERS  # a block finishes every (block time / threads)
    return first, float(np.median(later)) if later.size else float("nan")


def peak_memory_mib(n: int) -> float:
    """Peak resident memory (MiB) of a child process running ``kalcal verify -n n --no-report``."""
    # ru_maxrss survives exec on Linux (the child would report this process's peak); VmHWM belongs
    # to the child's own address space.
    code = (
        "import sys, tempfile\n"
        "from kalcal.cli import app\n"
        "out = tempfile.mkdtemp()\n"
        f"sys.argv = ['kalcal', 'verify', '-n', '{n}', '--out', out, '--no-report', '--long-run', '0']\n"
        "try:\n    app(prog_name='kalcal')\nexcept SystemExit:\n    pass\n"
        "status = open('/proc/self/status').read().split('VmHWM:')[1].split()\n"
        "print(status[0])\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return int(result.stdout.strip().splitlines()[-1]) / 1024  # kB -> MiB


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--n", type=int, default=300_000, help="realizations of the exact engine")
    parser.add_argument("--quick", action="store_true", help="smaller runs, no memory measurement")
    args = parser.parse_args()
    n = args.n // 10 if args.quick else args.n
    problem = accel_gps_problem(AccelGpsScenario())
    print(f"kalcal Monte Carlo benchmark: accel-gps, {WORKERS} threads, block {BLOCK_SIZE}, numpy {np.__version__}")
    run_monte_carlo(problem, 2 * BLOCK_SIZE, seed=0)  # compile and warm up

    exact_normals = problem.normals_per_realization("exact")
    no_pairs = accel_gps_problem(AccelGpsScenario(), residual_pairs=False)
    run_monte_carlo(no_pairs, BLOCK_SIZE, seed=0)
    (t_draw, c_draw), (t_exact, c_exact), (t_no_pairs, c_no_pairs) = (
        wall_and_cpu(3, lambda: raw_draws(n, exact_normals)),
        wall_and_cpu(3, lambda: run_monte_carlo(problem, n, seed=0)),
        wall_and_cpu(3, lambda: run_monte_carlo(no_pairs, n, seed=0)),
    )
    pair_flops = n * (2 * problem.truth.n_updates) * (2 * problem.truth.n_updates + 1)
    print(f"\nexact engine, N = {n:,}:")
    print(f"  raw draws ({exact_normals} normals/realization): {t_draw:7.3f} s")
    print(f"  kalcal, every statistic:                {t_exact:7.3f} s   ratio {t_exact / t_draw:5.2f}x the draws")
    print(f"  kalcal, without E[r_k r_j^T] pairs:      {t_no_pairs:7.3f} s   ratio {t_no_pairs / t_draw:5.2f}x the draws")
    print(f"  CPU time of the process (less sensitive to other load): draws {c_draw:.3f} s, every statistic "
          f"{c_exact / c_draw:.2f}x, without the pairs {c_no_pairs / c_draw:.2f}x")
    print(f"  the pairs alone are {pair_flops / 1e9:.0f} GFLOP (BLAS syrk): {(t_exact - t_no_pairs):.3f} s, "
          f"{pair_flops / 1e9 / max(t_exact - t_no_pairs, 1e-9) / WORKERS:.0f} GFLOP/s per thread")

    n_sampled = max(BLOCK_SIZE, n // 10)
    sampled_normals = problem.normals_per_realization("sampled")
    numpy_sampled = dataclasses.replace(problem, sampled_block=None)  # sample_accel_gps_errors, then the filter kernel
    (t_draw_s, c_draw_s), (t_sampled, c_sampled), (t_numpy_s, c_numpy_s) = (wall_and_cpu(2, f) for f in (
        lambda: raw_draws(n_sampled, sampled_normals),
        lambda: run_monte_carlo(problem, n_sampled, seed=0, engine="sampled"),
        lambda: run_monte_carlo(numpy_sampled, n_sampled, seed=0, engine="sampled")))
    print(f"\nsampled engine (every 200 Hz sample), N = {n_sampled:,}:")
    print(f"  raw draws ({sampled_normals} normals/realization): {t_draw_s:7.3f} s")
    print(f"  kalcal sampled engine:                    {t_sampled:7.3f} s   ratio {t_sampled / t_draw_s:5.2f}x the draws")
    print(f"  sampled in numpy, then the filter kernel: {t_numpy_s:7.3f} s   ratio {t_numpy_s / t_draw_s:5.2f}x the draws")
    print(f"  CPU time of the process: draws {c_draw_s:.3f} s, kalcal {c_sampled / c_draw_s:.2f}x, "
          f"numpy's sampling {c_numpy_s / c_draw_s:.2f}x")
    with engine.single_threaded_blas():
        one_block = alternating(
            5,
            lambda: block_generator(0, 0).standard_normal(BLOCK_SIZE * sampled_normals),
            lambda: problem.block_sums(block_generator(0, 0), BLOCK_SIZE, "sampled"),
            lambda: numpy_sampled.block_sums(block_generator(0, 0), BLOCK_SIZE, "sampled"),
        )
    print(f"  one block on one thread (thread CPU time): numpy's draws {one_block[0] * 1e3:.0f} ms, the compiled "
          f"block {one_block[1] / one_block[0]:.2f}x, numpy's sampling + the filter kernel {one_block[2] / one_block[0]:.2f}x")
    print(f"  normals per realization, sampled / exact: {sampled_normals / exact_normals:.1f}")

    print(f"\nin a fresh process, as the CLI pays it (N = {n:,}; numba's cache warm):")
    for mode in ("plain", "setup-first"):
        fresh = min((fresh_process(n, mode) for _ in range(2)), key=lambda run: run["wall"])
        first, later = block_times(fresh["marks"])
        setup = f"numba's loading timed apart {fresh['setup']:.3f} s, " if mode == "setup-first" else ""
        print(f"  {mode:12s} {setup}Monte Carlo {fresh['wall']:.3f} s = {fresh['wall'] / t_draw:.2f}x the draws; "
              f"first blocks done at {first:.3f} s, later blocks {later * 1e3:.0f} ms each per thread")

    with engine.single_threaded_blas():
        stacked = np.ascontiguousarray(problem.run_block(block_generator(0, 0), BLOCK_SIZE, "exact").residual
                                       .reshape(BLOCK_SIZE, -1).T)
        t_float64, t_float32 = alternating(
            15,
            lambda: np.triu(dsyrk(1.0, stacked.T, trans=1, lower=0)),
            lambda: np.triu(ssyrk(1.0, stacked.T.astype(np.float32), trans=1, lower=0)),
        )
    print(f"\npair sums of one block, one thread: float64 dsyrk (the engine's) {t_float64 * 1e3:.1f} ms, "
          f"float32 ssyrk with its conversion {t_float32 * 1e3:.1f} ms, factor {t_float64 / t_float32:.2f}x")

    unlimited = blas_free_run(problem, n)
    print(f"exact engine with BLAS free inside the blocks: {unlimited:.3f} s = {unlimited / t_exact:.2f}x the engine's (BLAS limited to one thread)")

    with engine.single_threaded_blas():
        per_block = block_parts(problem, no_pairs, stacked, exact_normals)
    (t_numpy_draws, t_kernel_draws, t_block, t_block_no_pairs, t_pairs) = per_block
    print(f"\none block of {BLOCK_SIZE}, one thread (thread CPU time, fastest of 9 rounds in turn):")
    for label, seconds in (
        (f"numpy's draws of its {exact_normals} normals/realization", t_numpy_draws),
        ("the kernel's own draws alone (the same values)", t_kernel_draws),
        ("compiled block without the pairs", t_block_no_pairs),
        ("compiled block, every statistic", t_block),
        ("its pair sums alone (dsyrk on the (Kp, n) buffer)", t_pairs),
    ):
        print(f"  {label:52s} {seconds * 1e3:6.1f} ms   {seconds / t_numpy_draws:.2f}x numpy's draws")

    t_numpy = best_of(3, lambda: MomentSums.from_block(problem.run_block(block_generator(0, 0), BLOCK_SIZE, "exact")))
    t_fused = best_of(3, lambda: problem.block_sums(block_generator(0, 0), BLOCK_SIZE, "exact"))
    print(f"\none block of {BLOCK_SIZE}, one thread: numpy reference {t_numpy * 1e3:.1f} ms, compiled {t_fused * 1e3:.1f} ms, "
          f"factor {t_numpy / t_fused:.1f}x")

    kalcal_rate = n / t_exact
    print("\nrealizations per second on the same filter (report's 3-state model, 150 updates):")
    print(f"  kalcal (exact engine, all statistics): {kalcal_rate:12,.0f}")
    count = 4 if args.quick else 20
    rate = filterpy_rate(problem, count, per_sample=True)
    print(f"  FilterPy, per-sample predict (6000 + 150 updates): {rate:8,.1f}   kalcal is {kalcal_rate / rate:,.0f}x")
    rate = filterpy_rate(problem, 5 * count, per_sample=False)
    print(f"  FilterPy, update-rate model (150 steps):           {rate:8,.1f}   kalcal is {kalcal_rate / rate:,.0f}x")
    rate = simdkalman_rate(problem, 20_000 if not args.quick else 2_000)
    print("  simdkalman: not installed" if rate is None else f"  simdkalman (filter only, vectorized):              {rate:8,.0f}   kalcal is {kalcal_rate / rate:,.1f}x")
    rate = dynamax_rate(problem, 20_000 if not args.quick else 2_000)
    print("  dynamax: not installed (pip install dynamax to compare)" if rate is None else f"  dynamax (jit + vmap, CPU):                          {rate:8,.0f}   kalcal is {kalcal_rate / rate:,.1f}x")

    if not args.quick:
        print("\npeak resident memory of `kalcal verify --no-report` (child process):")
        for size in (300_000, 3_000_000):
            print(f"  N = {size:>9,}: {peak_memory_mib(size):7.0f} MiB")
    print(f"\n(this process peaked at {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB)")


if __name__ == "__main__":
    main()
