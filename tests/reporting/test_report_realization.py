"""The report's redraw of one realization gives the engine's ``realization`` (every problem kind): its bits
through numpy, its values to rounding through the exact engine's compiled block."""

from __future__ import annotations

import numpy as np
import pytest

from kalcal.reporting.render import draw_realization
from kalcal.scenarios.model_file.model import parse_model
from kalcal.scenarios import build_scenario
from kalcal.montecarlo.engine import realization
from kalcal.montecarlo.problem import FixedGainProblem
from kalcal.montecarlo.scenarios import build_problem

from tests._helpers import reduced_model_text

REDUCED = reduced_model_text(gm_std=1.0, x0_truth=0.5)  # a truth with more states than the filter


def _assert_same(problem, seed, index, n, engine):
    shown = draw_realization(problem, seed, index, n, engine)
    one = realization(problem, seed, index, n, engine)
    if engine == "exact" and isinstance(problem, FixedGainProblem):  # the compiled block: fused, contracted
        # rounding of K = 30-150 updates, about K u = 2e-14 of each state's size; 1e-12 leaves room for the
        # gains carrying one state's rounding into another (measured: 4e-15 at most)
        scale = np.abs(one.estimate[0]).max(axis=0) + np.abs(one.error[0]).max(axis=0)
        for got, want in ((shown.error, one.error[0]), (shown.estimate, one.estimate[0])):
            assert np.all(np.abs(got - want) <= 1e-12 * scale)
            assert not np.array_equal(got, np.zeros_like(got))
    else:
        np.testing.assert_array_equal(shown.error, one.error[0])
        np.testing.assert_array_equal(shown.estimate, one.estimate[0])
    np.testing.assert_array_equal(shown.filter_cov, one.filter_cov[0])
    assert shown.error.shape == one.error.shape[1:] and shown.filter_cov.shape == one.filter_cov.shape[1:]


@pytest.mark.parametrize(
    ("engine", "index", "n"),
    [("exact", 0, 5000), ("exact", 4321, 5000), ("exact", 4999, 5000), ("sampled", 17, 300)],
)
def test_accel_gps_realization_is_the_engines(engine, index, n):
    """A full block, the short last block and the per-sample engine: the engine's values."""
    problem, _ = build_problem(build_scenario("accel-gps", None, ["scenario.duration=6"]), residual_pairs=True)
    _assert_same(problem, 3, index, n, engine)


def test_truth_of_its_own_states_realization_is_the_engines():
    """A model file whose truth has more states than the filter (error M x - xhat), through the compiled block."""
    problem, _ = build_problem(parse_model(REDUCED, "reduced.toml"))
    _assert_same(problem, 5, 4100, 4500, "exact")


@pytest.mark.parametrize(
    ("settings", "index", "n"),
    [([], 123, 500), ([], 4100, 9000), (["filter.form=note"], 8999, 9000),
     (["scenario.drift=random-walk"], 4097, 5000), (["scenario.excitation=reference"], 7, 300),
     (["scenario.excitation=reference", "scenario.drift=random-walk", "filter.form=note"], 4200, 4500)],
)  # fmt: skip
def test_data_dependent_gains_realization_is_the_engines(settings, index, n):
    """Scale-bias (its own P per realization) filters the shown series alone: the engine's values bit for
    bit, in a full block and in the short last one, for both drifts, both excitations and both forms."""
    problem, _ = build_problem(build_scenario("scale-bias", None, settings))
    _assert_same(problem, 4, index, n, "exact")


def test_index_outside_the_ensemble():
    problem, _ = build_problem(build_scenario("accel-gps", None, ["scenario.duration=6"]))
    with pytest.raises(ValueError, match=r"\[0, 100\), got 100"):
        draw_realization(problem, 3, 100, 100, "exact")
    from kalcal.montecarlo.accumulators import SumBuffers
    from kalcal.montecarlo.engine import block_generator

    with pytest.raises(ValueError, match=r"\[0, 100\), got 100"):
        problem.traced_realization(block_generator(3, 0), 100, 100)
    sums = SumBuffers.zeros(problem.truth.n_updates, 3, 2, 100, False)
    for traced in (100, -2):  # the compiled block itself reads the index unchecked
        with pytest.raises(ValueError, match=rf"\[-1, 100\), got {traced}"):
            problem._exact_block(block_generator(3, 0), 100, sums, traced)


def test_every_problem_shows_its_realization_through_the_protocol():
    """The report asks each problem for its realization (no test of what kind of problem it is): the member
    is the Problem protocol's, both problem classes have it with its signature, and an engine a problem
    lacks is refused as run_block refuses it."""
    import inspect

    from kalcal.errors import ConfigError
    from kalcal.montecarlo.engine import block_generator
    from kalcal.montecarlo.problem import Problem
    from kalcal.scenarios.scale_bias.problem import ScaleBiasProblem

    assert "shown_realization" in Problem.__dict__
    want = list(inspect.signature(Problem.shown_realization).parameters)
    for cls in (FixedGainProblem, ScaleBiasProblem):
        assert list(inspect.signature(cls.shown_realization).parameters) == want
    problem, _ = build_problem(build_scenario("scale-bias", None, []))
    with pytest.raises(ConfigError, match="'sampled' is not available"):
        problem.shown_realization(block_generator(3, 0), 100, 5, "sampled")
