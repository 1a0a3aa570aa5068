"""A nonlinear problem's draws: one standard normal per realization and update for each column of the
truth's noise factors that is not all zero, the count ``normals_per_realization`` states, in the block's
generator's stream exactly (the compiled kernel takes the same array: tests/scenarios/test_nonlinear_compiled.py
holds its sums to the numpy path's).

imu-3axis's Q has rank 2 of 11 (its 9 parameters kept, the pose's 2 tilts renewed): 2 + 3 normals per
update, not the 11 + 3 of a draw per state; the range-bearing example's Q and R have full rank and draw
d + p per update, as they always did."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from kalcal.montecarlo.engine import block_generator
from kalcal.scenarios import build_scenario, load_code_model
from kalcal.scenarios.nonlinear.problem import _drawn_factor

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "range_bearing.py"


def _problem(which: str):
    if which == "imu-3axis":  # the numpy path: the draws are the same on both (the compiled tests' oracle)
        return build_scenario("imu-3axis", None, ["filter.kind=ekf", "filter.compiled=no"]).problem()
    return load_code_model(str(EXAMPLE), ["scenario.updates=5", "filter.compiled=no"]).problem()


@pytest.mark.parametrize(("which", "per_update"), [("imu-3axis", 2 + 3), ("range-bearing", 4 + 2)])
def test_a_block_draws_the_normals_it_states_and_no_more(which, per_update):
    problem = _problem(which)
    truth = problem.scenario.loaded.truth
    k = problem.scenario.n_updates
    assert problem.normals_per_realization("exact") == truth.state_dim + k * per_update
    # the block leaves its generator where drawing that many normals in one call leaves it: every normal
    # it drew is counted, none skipped
    n = 37
    used, counted = block_generator(5, 2), block_generator(5, 2)
    problem.numpy_block_sums(used, n)
    counted.standard_normal(n * problem.normals_per_realization("exact"))
    np.testing.assert_array_equal(used.integers(0, 2**62, 8), counted.integers(0, 2**62, 8))


def test_the_drawn_factor_keeps_q_q_t_and_drops_only_zero_columns():
    """C C^T = Q over the columns kept (the truth's noise has Q's covariance), every dropped column zero."""
    truth = build_scenario("imu-3axis", None, []).loaded.truth
    c = _drawn_factor(truth.q)
    assert c.shape == (truth.state_dim, 2)
    np.testing.assert_allclose(c @ c.T, truth.q, rtol=0, atol=1e-15 * np.abs(truth.q).max())
    assert np.all(np.any(c != 0.0, axis=0))
    full = _drawn_factor(truth.r)  # R has full rank: its Cholesky factor, whole
    np.testing.assert_array_equal(full, np.linalg.cholesky(truth.r))
