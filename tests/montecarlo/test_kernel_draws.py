"""The exact kernel's own draws are numpy's: the same standard normals, in the same order, the same generator state after."""

from __future__ import annotations

import numpy as np
import pytest

from kalcal.scenarios.accel_gps.settings import AccelGpsScenario
from kalcal.models.config import apply_settings
from kalcal.montecarlo.engine import block_generator
from kalcal.montecarlo.kernels import standard_normals
from kalcal.scenarios.accel_gps.problem import accel_gps_problem


@pytest.mark.parametrize("bit_generator", [np.random.SFC64, np.random.PCG64, np.random.Philox])
@pytest.mark.parametrize("seed", [0, 5])
def test_standard_normals_equal_numpy_bit_for_bit(bit_generator, seed):
    """5 x 10^5 values: about 130 fall in the ziggurat's tail and some 5000 in its wedges, the paths
    that take exp and log."""
    shape = (5, 100_000)
    expected_rng = np.random.Generator(bit_generator(seed))
    expected = expected_rng.standard_normal(shape)
    rng = np.random.Generator(bit_generator(seed))
    got = np.empty(shape)
    standard_normals(rng, got)
    assert np.array_equal(got, expected)
    assert np.sum(np.abs(expected) > 3.6541528853610088) > 50  # the tail was reached
    # the generator is left where numpy leaves it: the next draws agree
    assert np.array_equal(rng.standard_normal(7), expected_rng.standard_normal(7))
    assert np.array_equal(rng.bit_generator.random_raw(16), expected_rng.bit_generator.random_raw(16))


@pytest.mark.parametrize("integration", ["euler", "trapezoid"])
@pytest.mark.parametrize("pairs", [True, False])
def test_the_kernel_draws_what_the_numpy_path_draws(integration, pairs):
    """After a compiled block the block's generator stands where ``sample_exact``'s draws leave it, and
    the sums agree with and without the pairs (the innovations formed in their rows, or in a buffer)."""
    scenario = apply_settings(AccelGpsScenario(), {"scenario.duration": 4.0, "scenario.integration": integration})
    problem = accel_gps_problem(scenario, residual_pairs=pairs)
    compiled, reference = block_generator(3, 1), block_generator(3, 1)
    sums = problem.block_sums(compiled, 257, "exact")
    problem.sample(reference, 257, "exact")
    assert np.array_equal(compiled.bit_generator.random_raw(16), reference.bit_generator.random_raw(16))
    other = accel_gps_problem(scenario, residual_pairs=not pairs).block_sums(block_generator(3, 1), 257, "exact")
    for name in ("error", "error_outer", "estimate_outer", "error_estimate", "nees", "nis", "residual", "residual_own"):
        assert np.array_equal(getattr(sums, name), getattr(other, name)), name
    assert (sums.residual_outer is not None) == pairs
