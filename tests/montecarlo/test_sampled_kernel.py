"""The sampled engine's compiled block against the numpy path (``sample_accel_gps_errors`` + ``run_with_gains``)
for every truth it simulates: same draws, same generator state after, the same sums to rounding."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from kalcal.scenarios.accel_gps.settings import AccelGpsScenario
from kalcal.models.config import apply_settings
from kalcal.montecarlo.accumulators import MomentSums
from kalcal.montecarlo.engine import block_generator
from kalcal.scenarios.accel_gps.problem import accel_gps_problem

#: every truth the sampled engine simulates: a constant, random-walk or Gauss-Markov bias, a scale-factor
#: error, both integration schemes, the discrete truth, a filter prior that differs from the truth's, and
#: other rates (the kernel's indexing depends on the samples per interval m: 10 there, 40 by default)
VARIANTS = {
    "constant bias": {},
    "random walk": {"truth.bias_walk_std": 1e-4},
    "gauss-markov": {"truth.bias_correlation_time": 5.0},
    "gauss-markov trapezoid": {"truth.bias_correlation_time": 5.0, "scenario.integration": "trapezoid"},
    "scale factor": {"truth.scale_std": 1e-3},
    "scale factor random walk": {"truth.scale_std": 1e-3, "truth.bias_walk_std": 1e-4},
    "trapezoid": {"scenario.integration": "trapezoid"},
    "discrete truth": {"scenario.truth": "discrete"},
    "prior mean offset": {"filter.position0_mean": 3.0},
    # one fix noise per interval instead of two (the kernel's draws and its measurement rows)
    "velocity-only fixes": {"scenario.gps_fixes": "velocity"},
    "velocity-only fixes, scale factor, trapezoid": {"scenario.gps_fixes": "velocity", "truth.scale_std": 1e-3,
                                                     "scenario.integration": "trapezoid"},
    "other rates": {"scenario.imu_rate": 100.0, "scenario.gps_rate": 10.0, "truth.bias_correlation_time": 5.0,
                    "scenario.integration": "trapezoid"},
}


def _problem(settings, pairs=True):
    scenario = apply_settings(AccelGpsScenario(), {"scenario.duration": 4.0, **settings})
    return accel_gps_problem(scenario, residual_pairs=pairs)


@pytest.mark.parametrize("name", sorted(VARIANTS))
def test_compiled_sampled_block_equals_the_numpy_path(name):
    problem = _problem(VARIANTS[name])
    assert problem.sampled_block is not None
    compiled, reference = block_generator(4, 2), block_generator(4, 2)
    fused = problem.block_sums(compiled, 257, "sampled")
    numpy_path = MomentSums.from_block(problem.run_block(reference, 257, "sampled"))
    # the kernel drew exactly the numpy path's normals: the generator stands at the same place
    assert np.array_equal(compiled.bit_generator.random_raw(16), reference.bit_generator.random_raw(16))
    assert fused.count == numpy_path.count == 257
    for field in dataclasses.fields(MomentSums):
        if field.name == "count":
            continue
        value, got = getattr(numpy_path, field.name), getattr(fused, field.name)
        if value is None:  # the whitened sums: kept only where P_k varies between realizations
            assert got is None, field.name
            continue
        scale = max(np.abs(value).max(), 1e-300)
        # rounding only: the two paths add the same float64 terms in another order (numpy's BLAS products),
        # ~3e-13 of the largest value at 4 s; a wrong term (a bias step, a noise std off by 1e-6) moves more
        assert np.abs(got - value).max() <= 1e-11 * scale, field.name


@pytest.mark.parametrize("name", ["constant bias", "gauss-markov"])
def test_the_sums_do_not_depend_on_keeping_the_pairs(name):
    """With the pairs the innovations are formed in their rows of the pair buffer, without them in a buffer
    of their own: every other sum is the same, bit for bit."""
    kept = _problem(VARIANTS[name]).block_sums(block_generator(4, 2), 257, "sampled")
    dropped = _problem(VARIANTS[name], pairs=False).block_sums(block_generator(4, 2), 257, "sampled")
    for field in ("error", "error_outer", "estimate_outer", "error_estimate", "nees", "nis", "residual", "residual_own"):
        assert np.array_equal(getattr(kept, field), getattr(dropped, field)), field
    assert kept.residual_outer is not None and dropped.residual_outer is None


def test_a_sampler_without_a_compiled_block_is_filtered_by_the_filter_kernel():
    """Without ``sampled_block`` the numpy sampler's arrays go through ``filter_block_moments``: the same
    sums to rounding, from the same draws."""
    problem = _problem(VARIANTS["gauss-markov"])
    fallback = dataclasses.replace(problem, sampled_block=None)
    compiled, reference = block_generator(4, 2), block_generator(4, 2)
    fused = problem.block_sums(compiled, 257, "sampled")
    filtered = fallback.block_sums(reference, 257, "sampled")
    assert np.array_equal(compiled.bit_generator.random_raw(16), reference.bit_generator.random_raw(16))
    for field in ("error", "error_outer", "estimate_outer", "error_estimate", "nees", "nis", "residual", "residual_outer"):
        value = getattr(filtered, field)
        assert np.abs(getattr(fused, field) - value).max() <= 1e-11 * np.abs(value).max(), field
