"""The engine's resources: blocks made as they are needed (memory flat in N), the wall time estimated
from a pilot, and a run too long or too big refused in one line before it runs on."""

from __future__ import annotations

import dataclasses
import os
import resource
import subprocess
import sys
import threading
import time
import tracemalloc

import pytest

from kalcal.errors import ConfigError
from kalcal.api.verification import ANNOUNCE_SECONDS, MAX_RUN_SECONDS, duration_text, run_estimate_check
from kalcal.scenarios.accel_gps.settings import AccelGpsScenario
from kalcal.models.config import apply_settings
from kalcal.montecarlo.engine import (
    RunEstimate,
    _chunks,
    block_count,
    block_generator,
    block_size_of,
    block_sizes,
    run_monte_carlo,
)
from kalcal.scenarios.accel_gps.problem import accel_gps_problem
from tests._helpers import sums_equal


def _problem():
    return accel_gps_problem(apply_settings(AccelGpsScenario(), {"scenario.duration": 2.0}))


class _Instant:
    """A problem whose blocks cost nothing: every block's sums are one precomputed part (its count set to
    the block's size), so that what a run holds besides the sums is all the engine's own."""

    engines = ("exact",)

    def __init__(self, delay: float = 0.0):
        real = _problem()
        self.info = real.info
        self.part = real.block_sums(block_generator(0, 0), 10, "exact")
        self.delay = delay
        self.calls = 0
        self.lock = threading.Lock()

    def block_sums(self, rng, n, engine):
        with self.lock:
            self.calls += 1
        if self.delay:
            time.sleep(self.delay)
        return dataclasses.replace(self.part, count=n)


class _Stop(Exception):
    pass


def test_block_layout_without_a_list():
    assert block_count(10, 4) == 3 and [block_size_of(10, b, 4) for b in range(3)] == [4, 4, 2]
    assert block_sizes(10, 4) == [4, 4, 2] and block_sizes(8, 4) == [4, 4]
    chunks = _chunks(1, 10, 4, 2)
    assert iter(chunks) is chunks  # an iterator, made as it is consumed
    assert list(chunks) == [[(1, 4), (2, 2)]]
    # 10^15 realizations: 2.4e11 blocks, the first task made at once
    huge = _chunks(0, 10**15, 4096, 3)
    assert next(huge) == [(0, 4096), (1, 4096), (2, 4096)]
    with pytest.raises(ValueError):
        block_count(0, 4)


def test_memory_of_a_run_does_not_grow_with_n():
    """N = 4.1e9 (10^6 blocks), stopped after its first blocks: the engine holds only the tasks in flight.
    Listing the blocks up front (2114039) took ~150 MB here before the first block ran."""
    problem = _Instant()

    def stop(done, total):
        if done > 0:
            raise _Stop

    for n in (4096 * 10, 4096 * 10**6):
        tracemalloc.start()
        try:
            with pytest.raises(_Stop):
                run_monte_carlo(problem, n, seed=1, workers=2, progress=stop)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        # the sums of a few blocks in flight (a few kB each) and the pool: far below a MB, whatever N
        assert peak < 2**20, (n, peak)


def test_the_lazy_blocks_give_the_numbers_of_the_listed_ones():
    """The same seed, N and block layout give the same bits as folding the listed blocks by hand."""
    problem = _problem()
    n, size = 5500, 1000
    parts = [problem.block_sums(block_generator(4, b), s, "exact") for b, s in enumerate(block_sizes(n, size))]
    by_hand = parts[0]
    for part in parts[1:]:
        by_hand = by_hand.merge(part)
    for workers, per_task in ((1, 1), (2, 4)):
        run = run_monte_carlo(problem, n, seed=4, workers=workers, block_size=size, blocks_per_task=per_task)
        assert sums_equal(run.sums, by_hand)


def test_the_estimate_comes_once_from_the_pilot_and_changes_no_number():
    """Blocks of 100 realizations that sleep 20 ms each on one thread: at most 5000 realizations/s, so a
    run of 20 000 takes at least 4 s, and the estimate says at least that (the sleep is a lower bound on
    each block's time; an upper bound would be a timed assertion)."""
    problem = _Instant(delay=0.02)
    seen = []
    run = run_monte_carlo(problem, 20_000, seed=2, workers=1, block_size=100, estimate=seen.append)
    assert len(seen) == 1
    estimate = seen[0]
    assert estimate.total == 20_000 and 0 < estimate.done < 20_000 and estimate.workers == 1
    assert estimate.realizations_per_s <= 100 / 0.02
    assert estimate.total_s >= 20_000 * 0.02 / 100 - 1e-9
    assert estimate.memory_bytes > 0
    plain = run_monte_carlo(problem, 20_000, seed=2, workers=1, block_size=100)
    assert sums_equal(run.sums, plain.sums)


def test_an_estimate_that_refuses_stops_the_run_at_once():
    problem = _Instant(delay=0.01)

    def refuse(estimate):
        raise ConfigError("too long")

    with pytest.raises(ConfigError, match="too long"):
        run_monte_carlo(problem, 10**7, seed=2, workers=2, block_size=100, estimate=refuse)
    assert problem.calls < 1000  # 10^5 blocks asked for; the pilot's half second ran a few hundred at most


def _estimate(total_s: float, memory_bytes: int = 10**6) -> RunEstimate:
    return RunEstimate(total_s, 1.0, 1e4, 100, 10**12, 2, memory_bytes)


def test_a_run_beyond_the_limit_is_refused_without_a_checkpoint_naming_the_ways_out():
    check = run_estimate_check(checkpoint=None, memory=None)
    with pytest.raises(ConfigError) as error:
        check(_estimate(2 * MAX_RUN_SECONDS))
    message = str(error.value)
    assert "\n" not in message and "estimated 2 days" in message and "more than the 24 h" in message
    for option in ("--workers", "--scheduler", "--checkpoint"):
        assert option in message
    run_estimate_check(checkpoint="run.ckpt", memory=None)(_estimate(2 * MAX_RUN_SECONDS))  # asked for: goes on
    run_estimate_check(checkpoint=None, memory=None, max_run_s=None)(_estimate(2 * MAX_RUN_SECONDS))
    check(_estimate(0.99 * MAX_RUN_SECONDS))


def test_memory_is_refused_only_beyond_what_is_available():
    check = run_estimate_check(checkpoint="run.ckpt", memory=10**9)
    check(_estimate(1.0, memory_bytes=10**9))  # fits exactly
    with pytest.raises(ConfigError, match=r"more than the 0.931 GiB available; use fewer threads \(--threads\)"):
        check(_estimate(1.0, memory_bytes=10**9 + 1))


def test_a_long_run_is_announced_and_a_short_one_is_not():
    notes = []
    check = run_estimate_check(checkpoint=None, notes=notes.append, memory=None)
    check(_estimate(ANNOUNCE_SECONDS / 2))
    assert notes == []
    check(_estimate(3 * 3600.0))
    assert notes == ["estimated wall time of the Monte Carlo: 3 h (10,000 realizations/s measured on 2 threads)"]


def test_durations_read_in_their_unit():
    assert [duration_text(s) for s in (5.0, 600.0, 86400.0, 40 * 86400.0, 3e9)] == [
        "5 s", "10 min", "24 h", "40 days", "95.1 years"
    ]


def test_verify_of_a_trillion_realizations_ends_in_one_line_and_exit_2(tmp_path):
    """``kalcal verify -n 10^12``: refused within seconds, in one line naming the ways out, under a 6 GiB
    address-space limit (2114039 listed 2.4e8 blocks first: a MemoryError traceback there, the kernel's
    kill without a limit)."""

    def limit_memory():
        resource.setrlimit(resource.RLIMIT_AS, (6 * 2**30, 6 * 2**30))

    started = time.monotonic()
    process = subprocess.run(
        [sys.executable, "-m", "kalcal", "verify", "-n", "1000000000000", "--out", str(tmp_path / "out")],
        capture_output=True, text=True, timeout=300, preexec_fn=limit_memory,
        env={**os.environ, "COLUMNS": "400"},
    )  # fmt: skip
    elapsed = time.monotonic() - started
    lines = process.stderr.strip().splitlines()
    assert process.returncode == 2, process.stderr[-3000:]
    assert len(lines) == 1 and lines[0].startswith("kalcal: error: -n 1,000,000,000,000: estimated "), lines
    for option in ("--workers", "--scheduler", "--checkpoint"):
        assert option in lines[0]
    assert not (tmp_path / "out" / "summary.json").exists()
    assert elapsed < 120, elapsed  # not a timing claim: the pilot is half a second; this only catches a hang
