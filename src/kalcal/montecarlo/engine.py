"""The batched Monte Carlo engine: blocks of realizations in threads, merged in block order.

Seeding: realizations are drawn in blocks of ``BLOCK_SIZE``; block b uses ``SFC64`` seeded with
``SeedSequence(seed, spawn_key=(b,))``, so realization i is the same whatever runs it, and block sums
folded in block order give identical statistics for a given seed and N: local threads (the compiled
kernels release the GIL), or Dask tasks on a cluster (``client``), in any grouping of blocks per task.
A checkpoint holds the fold of the blocks finished so far; a killed run resumes from it.
"""

from __future__ import annotations

import contextlib
import itertools
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor
from concurrent.futures import wait as futures_wait
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np
from threadpoolctl import ThreadpoolController

from kalcal.cpus import usable_cpus
from kalcal.errors import ConfigError
from kalcal.montecarlo.accumulators import MomentSums
from kalcal.montecarlo.checkpoint import fingerprint
from kalcal.montecarlo.checkpoint import load as load_checkpoint
from kalcal.montecarlo.checkpoint import save as save_checkpoint
from kalcal.montecarlo.problem import BlockResult, Problem, check_engine

BLOCK_SIZE = 4096
Progress = Callable[[int, int], None]


def block_sizes(n: int, block_size: int = BLOCK_SIZE) -> list[int]:
    """Sizes of the blocks that make up n realizations (all full but the last), as a list: for a test or
    a benchmark of a modest n (the engine itself never lists them: :func:`block_count`, :func:`block_size_of`)."""
    return [block_size_of(n, b, block_size) for b in range(block_count(n, block_size))]


def block_count(n: int, block_size: int = BLOCK_SIZE) -> int:
    """How many blocks make up n realizations: ceil(n / block_size)."""
    if n < 1:
        raise ValueError(f"number of realizations must be positive, got {n}")
    return -(-n // block_size)


def block_size_of(n: int, block: int, block_size: int = BLOCK_SIZE) -> int:
    """The size of block ``block`` of n realizations: ``block_size``, the last block what is left."""
    return min(block_size, n - block * block_size)


def check_seed(seed) -> None:
    """Raise ConfigError, one line, unless ``seed`` is a whole number >= 0 (what SeedSequence takes).

    Every run drawn from the engine's generators checks it here: verify, sweep and fit's bootstrap alike,
    before any work (and :func:`block_generator` again, for a caller that did not).
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ConfigError(f"--seed: expected a whole number >= 0, got {seed!r}")


def block_generator(seed: int, block: int) -> np.random.Generator:
    """The generator of block ``block`` (independent streams via SeedSequence spawning)."""
    check_seed(seed)
    child = np.random.SeedSequence(seed, spawn_key=(block,))
    return np.random.Generator(np.random.SFC64(child))


def run_block(problem: Problem, seed: int, block: int, size: int, engine: str) -> BlockResult:
    """Simulate and filter one block of realizations."""
    return problem.run_block(block_generator(seed, block), size, engine)


def realization(
    problem: Problem, seed: int, index: int, n: int, engine: str, block_size: int = BLOCK_SIZE
) -> BlockResult:
    """Realization ``index`` of the n-realization ensemble drawn with ``seed``, as a block of one.

    Reruns its whole block at that block's size in the ensemble (the last block is shorter, and the
    draws of a block are interleaved across its realizations). ``filter_cov_sum`` is that
    realization's own P, (K, d, d) (the block's ``filter_cov``, which every problem gives): the same for
    every realization of a fixed-gain filter, its own for a filter whose gains depend on the data
    (scale-bias).
    """
    if not 0 <= index < n:
        raise ValueError(f"realization index must lie in [0, {n}), got {index}")
    block, offset = divmod(index, block_size)
    result = run_block(problem, seed, block, block_size_of(n, block, block_size), engine)
    one = slice(offset, offset + 1)
    own = np.array(result.filter_cov[offset])
    normalized = None if result.normalized_residual is None else result.normalized_residual[one]
    return BlockResult(*(a[one] for a in result[:5]), own, own[None], normalized)


@dataclass(frozen=True)
class MonteCarloRun:
    """The merged sums of a run and what it cost."""

    sums: MomentSums
    seed: int
    engine: str
    block_size: int
    wall_s: float
    workers: int
    resumed_blocks: int = 0  #: blocks taken from a checkpoint instead of computed


def _thread_pools() -> ThreadpoolController:
    """This process's thread pools (BLAS, OpenMP) as loaded now: looked up at each outermost entry of
    :func:`single_threaded_blas` (~2 ms, once per run or Dask task of several blocks), because a BLAS
    loaded after a first lookup (scipy's own, say) would otherwise keep its threads."""
    return ThreadpoolController()


_blas_lock = threading.Lock()
_blas_users = 0
_blas_limiter = None


@contextlib.contextmanager
def single_threaded_blas():
    """Hold this process's BLAS to one thread while any caller is inside (the engine's parallelism is
    over blocks).

    The limit is process-global, so it is counted, not nested: the first caller to enter sets it, the
    last to leave restores the original, and callers in between (a run's worker threads, the tasks of a
    multi-threaded Dask worker) change nothing. A local run enters once, around its whole pool.
    """
    global _blas_users, _blas_limiter
    with _blas_lock:
        if _blas_users == 0:
            _blas_limiter = _thread_pools().limit(limits=1, user_api="blas")
        _blas_users += 1
    try:
        yield
    finally:
        with _blas_lock:
            _blas_users -= 1
            if _blas_users == 0:
                _blas_limiter.restore_original_limits()
                _blas_limiter = None


def block_task(problem: Problem, seed: int, blocks: list[tuple[int, int]], engine: str) -> list[tuple[int, MomentSums]]:
    """The sums of consecutive blocks ``[(index, size), ...]``, each on its own (a thread or a Dask task).

    BLAS is held to one thread (:func:`single_threaded_blas`; inside a local run that limit is already
    in force and this only counts).
    """
    with single_threaded_blas():
        return [(b, problem.block_sums(block_generator(seed, b), size, engine)) for b, size in blocks]


def _merge_in_order(pending: dict[int, MomentSums], merged: MomentSums | None, next_block: int):
    """Fold the finished blocks that continue the prefix [0, next_block) into ``merged``."""
    while next_block in pending:
        part = pending.pop(next_block)
        merged = part if merged is None else merged.merge(part)
        next_block += 1
    return merged, next_block


def _chunks(first: int, n: int, block_size: int, per_task: int) -> Iterator[list[tuple[int, int]]]:
    """The tasks' lists of consecutive ``(block, size)`` from block ``first`` on, made as they are asked for:
    the engine holds only the tasks in flight, so its memory does not grow with n (n = 10^12 is 2.4 x 10^8
    blocks; listed up front, they took more memory than a usual machine has)."""
    count = block_count(n, block_size)
    for start in range(first, count, per_task):
        yield [(b, block_size_of(n, b, block_size)) for b in range(start, min(start + per_task, count))]


@dataclass(frozen=True)
class RunEstimate:
    """What the first :data:`PILOT_S` seconds of a run measured, and what they predict for the whole.

    Attributes
    ----------
    total_s : float
        Predicted wall time of the whole run (s): the time so far plus the realizations left at the rate
        measured since the first task finished (the first tasks also load the compiled kernels).
    elapsed_s : float
        Wall time so far (s).
    realizations_per_s : float
        The measured rate (realizations per second, all workers together).
    done, total : int
        Realizations finished (or resumed from the checkpoint) and asked for.
    workers : int
        Threads, or the Dask cluster's threads.
    memory_bytes : int
        The run's sums at once in the usual case (bytes): one task's sums as measured, times twice the
        tasks in flight (those running, and as many finished ones waiting for their turn in the
        block-order fold), plus the fold itself. It does not grow with N. It is an estimate, not a bound:
        a task that stalls (a Dask worker lost and its task rerun) holds the fold back, and every task
        finished after it waits in memory until it ends; the blocks' own working arrays (per thread or
        worker, freed as each block ends) are not in it.
    """

    total_s: float
    elapsed_s: float
    realizations_per_s: float
    done: int
    total: int
    workers: int
    memory_bytes: int


#: Seconds after the first task finishes over which the rate of a run is measured for its estimate.
PILOT_S = 0.5

Estimate = Callable[[RunEstimate], None]


def _nbytes(sums: MomentSums) -> int:
    """Bytes of a MomentSums' arrays."""
    groups = sum(a.nbytes for g in sums.effect_blocks or () for a in g[1:])
    return groups + sum(v.nbytes for v in vars(sums).values() if isinstance(v, np.ndarray))


def run_monte_carlo(
    problem: Problem,
    n: int,
    seed: int = 0,
    *,
    engine: str = "exact",
    workers: int | None = None,
    block_size: int = BLOCK_SIZE,
    progress: Progress | None = None,
    client=None,
    blocks_per_task: int = 1,
    checkpoint: str | Path | None = None,
    checkpoint_key: dict | None = None,
    estimate: Estimate | None = None,
) -> MonteCarloRun:
    """Run n realizations of ``problem`` and return their merged sums.

    Parameters
    ----------
    problem : Problem
    n : int
        Realizations.
    seed : int
        Root seed; block b draws from SeedSequence(seed, spawn_key=(b,)).
    engine : str
        One of ``problem.engines``.
    workers : int, optional
        Threads when ``client`` is None (default: the cores available to this process).
    block_size : int
        Realizations per block: part of the random stream's definition.
    progress : callable, optional
        ``progress(done, total)`` as blocks finish, in realizations.
    client : dask.distributed.Client, optional
        Run the blocks as Dask tasks on its cluster instead of local threads.
    blocks_per_task : int
        Consecutive blocks per task (the batch): changes scheduling, never the numbers.
    checkpoint : path, optional
        Resume from this file if it exists and save the merged sums to it as blocks finish.
    checkpoint_key : dict, optional
        What else identifies the run for the checkpoint (the scenario's settings); N, seed, engine and
        block size are always included.
    estimate : callable, optional
        ``estimate(RunEstimate)``, called once, :data:`PILOT_S` seconds after the first task finished
        (not at all for a run done by then): the predicted wall time and memory. An exception it raises
        stops the run (the tasks in flight end first) and reaches the caller.

    Returns
    -------
    MonteCarloRun
        Whatever runs the blocks and however they are grouped, the sums are folded in block order, so
        a given seed and N give identical numbers.

    Notes
    -----
    The blocks' list is never built: tasks are made as earlier ones finish, at most two per worker in
    flight, so the memory a run holds does not depend on N.
    """
    check_engine(problem, engine)
    check_seed(seed)
    count = block_count(n, block_size)
    digest = fingerprint({"n": n, "seed": seed, "engine": engine, "block_size": block_size, **(checkpoint_key or {})})
    start = time.perf_counter()
    merged: MomentSums | None = None
    next_block = 0
    if checkpoint is not None and (saved := load_checkpoint(checkpoint, digest)) is not None:
        merged, next_block = saved
    resumed = next_block
    done = min(n, next_block * block_size)
    if progress is not None:
        progress(done, n)
    chunks = _chunks(next_block, n, block_size, max(1, int(blocks_per_task)))
    pending: dict[int, MomentSums] = {}

    if client is None:
        workers = max(1, workers or usable_cpus())
        executor = ThreadPoolExecutor(max_workers=workers)
        # the BLAS limit is process-global: set once for the whole run (entered first, left last)
        contexts = [single_threaded_blas(), executor]
        submit, first_done = executor.submit, partial(futures_wait, return_when=FIRST_COMPLETED)
        in_flight_limit = 2 * workers
    else:
        from distributed import wait as dask_wait

        contexts = []
        workers = max(1, sum(client.nthreads().values()))
        submit = partial(client.submit, pure=False)
        first_done = partial(dask_wait, return_when="FIRST_COMPLETED")
        in_flight_limit = 2 * workers

    # the pilot: the rate is measured from the first finished task on, after the kernels are loaded
    pilot: tuple[float, int] | None = None  # (time, realizations done) when the first task finished
    part_bytes = 0
    with contextlib.ExitStack() as stack:
        for context in contexts:
            stack.enter_context(context)
        queue = chunks
        running = {submit(block_task, problem, seed, chunk, engine) for chunk in itertools.islice(queue, in_flight_limit)}
        while running:
            finished, running = first_done(running)
            running = set(running)
            for future in finished:
                for b, part in future.result():
                    pending[b] = part
                    done += block_size_of(n, b, block_size)
                    part_bytes = part_bytes or _nbytes(part)
                for chunk in itertools.islice(queue, 1):
                    running.add(submit(block_task, problem, seed, chunk, engine))
            before = next_block
            merged, next_block = _merge_in_order(pending, merged, next_block)
            if checkpoint is not None and next_block > before:
                save_checkpoint(checkpoint, merged, next_block, digest)
            if progress is not None:
                progress(done, n)
            if estimate is not None and running:
                now = time.perf_counter()
                if pilot is None:
                    pilot = (now, done)
                elif now - pilot[0] >= PILOT_S and done > pilot[1]:
                    rate = (done - pilot[1]) / (now - pilot[0])
                    per_task = max(1, int(blocks_per_task))
                    estimate(
                        RunEstimate(
                            total_s=now - start + (n - done) / rate,
                            elapsed_s=now - start,
                            realizations_per_s=rate,
                            done=done,
                            total=n,
                            workers=workers,
                            memory_bytes=(2 * in_flight_limit * per_task + 1) * part_bytes,
                        )
                    )
                    estimate = None
    if merged is None or pending or next_block != count:
        raise RuntimeError("Monte Carlo run ended with blocks missing")  # a bug, not a user error
    return MonteCarloRun(merged, seed, engine, block_size, time.perf_counter() - start, workers, resumed)
