"""The compiled EKF block kernel of a nonlinear model against the batched numpy path it replaces: the same
draws, the same block sums to rounding (1e-10 relative), the same sums whatever the workers, and the
models and filters that keep the numpy path saying why."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from kalcal.core import xmath as xm
from kalcal.core.nonlinear import NonlinearModel, load_nonlinear_model
from kalcal.montecarlo.engine import block_generator, run_monte_carlo
from kalcal.scenarios import load_code_model

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "range_bearing.py"
rb = load_nonlinear_model(EXAMPLE)


def _linear(r_scale: float) -> NonlinearModel:
    """The constant-velocity f with a linear measurement (its EKF is the Kalman filter)."""
    m = rb.filter
    return NonlinearModel(
        f=m.f, h=lambda x, data: xm.stack([x[:, 0] + 0.5 * x[:, 2], x[:, 1]]), q=m.q, r=np.diag([1.0, 4.0]) * r_scale,
        x0=m.x0, p0=m.p0, dt=1.0, state_names=m.state_names, state_units=m.state_units,
        measurement_names=("a", "b"), measurement_units=("m", "m"),
    )


def _assert_same_sums(compiled, oracle, rtol=1e-10):
    """Every field of two MomentSums within rtol of the oracle's largest entry of that field."""
    for f in dataclasses.fields(oracle):
        a, b = getattr(compiled, f.name), getattr(oracle, f.name)
        if f.name == "count":
            assert a == b
            continue
        assert (a is None) == (b is None), f.name
        if b is None:
            continue
        assert a.shape == b.shape, f.name
        assert np.all(np.isfinite(a)), f.name
        scale = np.max(np.abs(b))
        assert np.max(np.abs(a - b)) <= rtol * scale, (f.name, np.max(np.abs(a - b)) / scale)


@pytest.mark.parametrize("n", [300, 64])  # 300: a last tile of 44 realizations in 64 lanes
def test_range_bearing_compiled_block_sums_equal_the_numpy_path(n):
    problem = load_code_model(str(EXAMPLE), ["scenario.updates=12"]).problem()
    assert problem.compiled_path == (True, "")
    compiled = problem.block_sums(block_generator(5, 0), n, "exact")
    oracle = problem.numpy_block_sums(block_generator(5, 0), n, "exact")
    _assert_same_sums(compiled, oracle)


def test_linear_model_with_another_truth_compiled_block_sums_equal_the_numpy_path():
    """A filter that believes R x 4 against its truth: two models, two sets of printed functions."""
    problem = load_code_model((_linear(1.0), _linear(4.0)), ["scenario.updates=7"]).problem()
    assert problem.compiled_path[0]
    compiled = problem.block_sums(block_generator(2, 3), 150, "exact")
    oracle = problem.numpy_block_sums(block_generator(2, 3), 150, "exact")
    _assert_same_sums(compiled, oracle)


def test_compiled_run_same_seed_same_sums_whatever_the_workers_and_the_numpy_runs():
    problem = load_code_model(str(EXAMPLE), ["scenario.updates=6"]).problem()
    numpy_problem = dataclasses.replace(problem, compiled=False)
    assert numpy_problem.compiled_path == (False, "the numpy path was asked for")
    one = run_monte_carlo(problem, 9000, 11, workers=1).sums
    two = run_monte_carlo(problem, 9000, 11, workers=2).sums
    for f in dataclasses.fields(one):
        a, b = getattr(one, f.name), getattr(two, f.name)
        assert (a is None and b is None) or np.array_equal(a, b), f.name
    _assert_same_sums(one, run_monte_carlo(numpy_problem, 9000, 11, workers=1).sums)


def test_filters_and_models_the_kernel_does_not_take_keep_the_numpy_path_and_say_why():
    for kind in ("iekf", "ukf"):
        problem = load_code_model(str(EXAMPLE), [f"filter.kind={kind}"]).problem()
        compiled, reason = problem.compiled_path
        assert not compiled and kind.upper() in reason and "numpy" in reason
    m = _linear(1.0)
    explicit = dataclasses.replace(m, h_jacobian=lambda x, data: np.asarray(m.measurement_jacobian(x, data)))
    problem = load_code_model((explicit, explicit), ["scenario.updates=3"]).problem()
    compiled, reason = problem.compiled_path
    assert not compiled and "explicit Jacobians" in reason
    # and it runs, on the numpy path
    assert problem.block_sums(block_generator(0, 0), 20, "exact").count == 20


class _PlantedNaN:
    """A generator whose draws are another's, with one measurement noise made NaN (a missing measurement
    of realization 5 at update 3); its state is the wrapped one's, so a path that restores it redraws the same."""

    def __init__(self, seed):
        self._rng = block_generator(seed, 0)
        self.bit_generator = self._rng.bit_generator

    def standard_normal(self, shape):
        out = self._rng.standard_normal(shape)
        if len(shape) == 3:
            out[3, 5, shape[2] - 1] = np.nan
        return out


def test_a_missing_measurement_stops_the_kernel_and_the_block_runs_on_the_numpy_path_from_the_same_draws():
    problem = load_code_model(str(EXAMPLE), ["scenario.updates=6"]).problem()
    assert problem.compiled_path[0]
    assert problem._compiled_block_sums(_PlantedNaN(4), 100) is None  # the kernel stops at the NaN
    got = problem.block_sums(_PlantedNaN(4), 100, "exact")
    want = problem.numpy_block_sums(_PlantedNaN(4), 100, "exact")
    for f in dataclasses.fields(want):
        a, b = getattr(got, f.name), getattr(want, f.name)
        assert (a is None and b is None) or np.array_equal(a, b, equal_nan=True), f.name
    assert np.isnan(want.nis[3])  # the numpy path's own rule for the missing measurement shows in the sums


@pytest.mark.slow  # numba types most of the kernel before it meets the failing call: about a minute
def test_printed_code_numba_cannot_compile_keeps_the_numpy_path_and_says_why(monkeypatch, tmp_path):
    from kalcal.scenarios.nonlinear import compiled as compiled_module

    printed = compiled_module.model_source

    def broken(model, prefix):  # a function numba does not know, as a model's printed code might call
        return printed(model, prefix).replace("out[0, j] = float(", "out[0, j] = float(math.fsum(object()) + ")

    monkeypatch.setenv("KALCAL_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(compiled_module, "model_source", broken)
    model = _linear(3.0)  # a model of its own: no kernel derived for it before
    problem = load_code_model(model, ["scenario.updates=4"]).problem()
    assert problem.compiled_path[0]  # printed and imported: numba compiles at the first block
    got = problem.block_sums(block_generator(9, 0), 50, "exact")
    compiled, reason = problem.compiled_path
    assert not compiled and "numba cannot compile" in reason
    _assert_same_sums(got, problem.numpy_block_sums(block_generator(9, 0), 50, "exact"), rtol=0.0)
