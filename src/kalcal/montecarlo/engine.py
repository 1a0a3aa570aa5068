"""The batched Monte Carlo engine: blocks of realizations in threads, merged in block order.

Seeding: realizations are drawn in blocks of ``BLOCK_SIZE``; block b uses ``SFC64`` seeded with
``SeedSequence(seed).spawn(...)[b]``, so realization i is the same whatever the number of threads or
workers, and block sums merged in block order give identical statistics for a given seed and N.
Threads share the work because numpy releases the GIL while it draws random numbers and does array
arithmetic; BLAS is held to one thread per block so that threads do not oversubscribe the cores.
"""

from __future__ import annotations

import itertools
import os
import time
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from dataclasses import dataclass

import numpy as np
from threadpoolctl import threadpool_limits

from kalcal.montecarlo.accumulators import MomentSums
from kalcal.montecarlo.problem import BlockResult, Problem

BLOCK_SIZE = 4096
Progress = Callable[[int, int], None]


def block_sizes(n: int, block_size: int = BLOCK_SIZE) -> list[int]:
    """Sizes of the blocks that make up n realizations (all full but the last)."""
    if n < 1:
        raise ValueError(f"number of realizations must be positive, got {n}")
    full, rest = divmod(n, block_size)
    return [block_size] * full + ([rest] if rest else [])


def block_generator(seed: int, block: int) -> np.random.Generator:
    """The generator of block ``block`` (independent streams via SeedSequence spawning)."""
    child = np.random.SeedSequence(seed, spawn_key=(block,))
    return np.random.Generator(np.random.SFC64(child))


def run_block(problem: Problem, seed: int, block: int, size: int, engine: str) -> BlockResult:
    """Simulate and filter one block of realizations."""
    return problem.run_block(block_generator(seed, block), size, engine)


def realization(problem: Problem, seed: int, index: int, engine: str, block_size: int = BLOCK_SIZE) -> BlockResult:
    """The ``index``-th realization of the ensemble drawn with ``seed``, as a block of one.

    Reruns its whole block (the draws of a block are interleaved across its realizations).
    """
    block, offset = divmod(index, block_size)
    result = run_block(problem, seed, block, block_size, engine)
    return BlockResult(*(a[offset : offset + 1] for a in result[:5]), result.filter_cov_sum / block_size)


@dataclass(frozen=True)
class MonteCarloRun:
    """The merged sums of a run and what it cost."""

    sums: MomentSums
    seed: int
    engine: str
    block_size: int
    wall_s: float
    workers: int


def _merge_in_order(pending: dict[int, MomentSums], merged: MomentSums | None, next_block: int):
    while next_block in pending:
        part = pending.pop(next_block)
        merged = part if merged is None else merged.merge(part)
        next_block += 1
    return merged, next_block


def run_monte_carlo(
    problem: Problem,
    n: int,
    seed: int = 0,
    *,
    engine: str = "exact",
    workers: int | None = None,
    block_size: int = BLOCK_SIZE,
    progress: Progress | None = None,
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
        Threads (default: the number of cores available to this process).
    block_size : int
        Realizations per block: part of the random stream's definition, so results depend on it only
        through which draws make up each realization.
    progress : callable, optional
        ``progress(done, total)`` after each block, in realizations.
    """
    if engine not in problem.engines:
        raise ValueError(f"engine {engine!r} is not available (have {', '.join(problem.engines)})")
    sizes = block_sizes(n, block_size)
    workers = max(1, workers or len(os.sched_getaffinity(0)))
    start = time.perf_counter()
    merged: MomentSums | None = None
    pending: dict[int, MomentSums] = {}
    next_block, done = 0, 0

    def task(b: int) -> tuple[int, MomentSums]:
        return b, problem.block_sums(block_generator(seed, b), sizes[b], engine)

    with threadpool_limits(limits=1, user_api="blas"), ThreadPoolExecutor(max_workers=workers) as pool:
        queue = iter(range(len(sizes)))
        running = {pool.submit(task, b) for b in itertools.islice(queue, 2 * workers)}
        while running:
            finished, running = wait(running, return_when=FIRST_COMPLETED)
            for future in finished:
                b, part = future.result()
                pending[b] = part
                done += sizes[b]
                for b_next in queue:
                    running.add(pool.submit(task, b_next))
                    break
            merged, next_block = _merge_in_order(pending, merged, next_block)
            if progress is not None:
                progress(done, n)
    assert merged is not None and not pending
    return MonteCarloRun(merged, seed, engine, block_size, time.perf_counter() - start, workers)
