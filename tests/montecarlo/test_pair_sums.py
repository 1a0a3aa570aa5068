"""The pair sums E[r_k r_j^T], summed in float32 runs and float64 across them, against float64 sums of the
same innovations, within the stated bounds (``pair_sum_error``, ``pair_z_error``)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from kalcal.models.accel_gps import AccelGpsScenario
from kalcal.models.config import apply_settings
from kalcal.montecarlo.accumulators import (
    FLOAT64_ROUNDOFF,
    PAIR_RUN,
    MomentSums,
    ResidualProducts,
    ensemble_statistics,
    pair_sum_error,
    pair_z_error,
)
from kalcal.montecarlo.engine import block_generator, block_sizes
from kalcal.montecarlo.scenarios import accel_gps_problem
from kalcal.verification.whiteness import check_residual_whiteness


def _stacked(residual: np.ndarray) -> np.ndarray:
    """(n, K, p) innovations as the (K p, n) columns the pair sums take."""
    n, k, p = residual.shape
    return np.ascontiguousarray(residual.reshape(n, k * p).T)


def _float64_upper(stacked: np.ndarray) -> np.ndarray:
    return np.triu(stacked @ stacked.T)


def _scale(upper: np.ndarray) -> np.ndarray:
    """sqrt(S_aa S_bb) for every pair."""
    root = np.sqrt(np.diagonal(upper))
    return np.outer(root, root)


@pytest.fixture(scope="module")
def problem():
    return accel_gps_problem(apply_settings(AccelGpsScenario(), {"scenario.duration": 10}))


@pytest.mark.parametrize("run", [PAIR_RUN, 100])
def test_one_block_within_its_bound(problem, run):
    stacked = _stacked(problem.run_block(block_generator(3, 0), 2500, "exact").residual)
    computed = ResidualProducts.upper(stacked, run)
    exact = _float64_upper(stacked)
    # the float64 reference rounds too: at most gamma_n (float64) times the same scale
    reference_error = 2500 * FLOAT64_ROUNDOFF / (1 - 2500 * FLOAT64_ROUNDOFF)
    bound = (pair_sum_error(2500, run) + reference_error) * _scale(exact)
    assert np.all(np.abs(computed - exact) <= bound)
    assert np.all(np.tril(computed, -1) == 0)  # the upper triangle only, as before


def test_runs_of_one_add_the_float32_products_in_float64():
    stacked = np.random.default_rng(4).standard_normal((6, 5))
    single = stacked.astype(np.float32)
    expected = np.zeros((6, 6))
    for column in single.T:  # each run: one product, rounded to float32; the runs summed in float64
        expected += np.outer(column, column).astype(np.float64)
    assert np.array_equal(ResidualProducts.upper(stacked, 1), np.triu(expected))


def test_whiteness_pairs_statistic_within_its_bound(problem):
    """Blocks merged as the engine merges them: every pair's z, and the check's largest |z|, move by at most
    pair_z_error from the z of float64 sums of the same innovations."""
    n = 6000
    parts, columns = [], []
    for b, size in enumerate(block_sizes(n, 2500)):  # three blocks, each of several float32 runs
        block = problem.run_block(block_generator(3, b), size, "exact")
        parts.append(MomentSums.from_block(block))
        columns.append(_stacked(block.residual))
    merged = parts[0]
    for part in parts[1:]:
        merged = merged.merge(part)
    exact_upper = _float64_upper(np.concatenate(columns, axis=1))
    z = np.sqrt(n) * exact_upper / _scale(exact_upper)
    z_computed = np.sqrt(n) * merged.residual_outer / _scale(merged.residual_outer)
    upper = np.triu(np.ones_like(z, dtype=bool), 1)
    assert np.all(np.abs(z_computed - z)[upper] <= pair_z_error(n, z[upper], 2500))

    float64 = dataclasses.replace(merged, residual_outer=exact_upper)
    info = problem.info
    exact_check = check_residual_whiteness(ensemble_statistics(float64), info, 0.99)
    computed_check = check_residual_whiteness(ensemble_statistics(merged), info, 0.99)
    worst = exact_check.statistic
    assert abs(computed_check.statistic - worst) <= pair_z_error(n, worst, 2500)


def test_bound_at_the_default_run():
    """The figure docs/verification.md quotes: at N = 3 x 10^5 a pair's z moves by at most 0.034 (z near 0)."""
    assert 0.03 < pair_z_error(300_000) < 0.034


def test_same_bits_whatever_the_callers_blas_threads():
    """OpenBLAS's ssyrk rounds differently with more threads: the pair sums hold BLAS to one."""
    from threadpoolctl import threadpool_limits

    stacked = np.random.default_rng(6).standard_normal((300, 2048))
    with threadpool_limits(limits=1, user_api="blas"):
        one = ResidualProducts.upper(stacked)
    with threadpool_limits(limits=2, user_api="blas"):
        two = ResidualProducts.upper(stacked)
    assert np.array_equal(one, two)
