"""The benchmarks' profiles of one block run it as the Monte Carlo engine does: BLAS on one thread for the
whole block (the pair sums inside ``block_sums`` included), so that BLAS's threads waiting for a loaded
core are not counted as the kernel's time."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import SimpleNamespace

import pytest
from threadpoolctl import threadpool_info, threadpool_limits

ROOT = Path(__file__).resolve().parents[1]


def _module(name: str):
    spec = importlib.util.spec_from_file_location(f"_bench_{name}", ROOT / "benchmarks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _blas_threads() -> list[int]:
    return [pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"]


class _Recording:
    """A problem whose block records BLAS's thread counts while it runs."""

    def __init__(self):
        truth = SimpleNamespace(state_dim=4, measurement_dim=2)
        self.scenario = SimpleNamespace(n_updates=3, loaded=SimpleNamespace(truth=truth))
        self.seen: list[list[int]] = []

    def block_sums(self, rng, n, engine):
        self.seen.append(_blas_threads())

    def normals_per_realization(self, engine):
        """x_0's 4 normals and, at each of the 3 updates, a full-rank Q's 4 and R's 2."""
        return 4 + 3 * (4 + 2)


@pytest.mark.parametrize("bench, profile", [("bench_nonlinear", "profile"), ("bench_imu_3axis", "profile")])
def test_a_benchmark_profile_runs_the_whole_block_with_blas_on_one_thread(bench, profile, capsys):
    if not _blas_threads():
        pytest.fail("no BLAS thread pool that threadpoolctl can see: the check cannot be made")
    problem = _Recording()
    with threadpool_limits(limits=2, user_api="blas"):  # BLAS multi-threaded around the profile
        assert set(_blas_threads()) == {2}
        getattr(_module(bench), profile)(problem, 16)
    assert problem.seen and all(set(seen) == {1} for seen in problem.seen), problem.seen
    assert "profile of one block" in capsys.readouterr().out
