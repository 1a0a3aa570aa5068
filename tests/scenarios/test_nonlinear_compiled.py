"""The compiled EKF block kernel of a nonlinear model against the batched numpy path it replaces: the same
draws, the same block sums to rounding (1e-10 relative to each sum's largest entry, each quantity of the
effect sums apart) and the same shape histograms count for count,
the same sums whatever the workers, and the models and filters that keep the numpy path saying why; and
``filter.compiled``'s policy (auto: compiled where it is already or the planned run repays the compile).

The tests that run the kernel force it (``filter.compiled=yes``) and keep to four distinct printed
modules, range-bearing's, the linear pair's, imu-3axis's pose model and a model with known inputs and a
correlated R: each compiles for about a minute on a cold cache.

imu-3axis's EKF runs the same kernel with the checks on 9 of its 11 states (the current pose's 2 tilts
are nuisance states, renewed at each pose by the model's own f and Q: f sets them to the nominal pose,
Q draws the truth's new tilts and gives the filter's prior, the predict zeroes their cross covariances):
held to the numpy path the same way."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from kalcal.core import xmath as xm
from kalcal.core.nonlinear import NonlinearModel, load_nonlinear_model
from kalcal.montecarlo.engine import block_count, block_generator, run_monte_carlo
from kalcal.scenarios import build_scenario, load_code_model
from kalcal.scenarios.nonlinear.problem import _TILE

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


def _same_groups(a, b, equal_nan=False) -> bool:
    """Two MomentSums' ``effect_blocks`` equal group for group, bit for bit."""
    if a is None or b is None:
        return a is None and b is None
    return len(a) == len(b) and all(
        x[0] == y[0] and all(np.array_equal(u, v, equal_nan=equal_nan) for u, v in zip(x[1:], y[1:])) for x, y in zip(a, b)
    )


def _assert_same_sums(compiled, oracle, rtol=1e-10, layout=None):
    """Every field of two MomentSums within rtol of the oracle's largest entry of that field; the effect
    sums, a flat array of quantities of different sizes, each quantity within rtol of its own largest entry
    (``layout``, the problem's :class:`EffectLayout`, names them; required where the sums carry them)."""
    if oracle.effect is not None:
        assert layout is not None, "the effect sums' layout, to compare each quantity on its own scale"
        assert compiled.effect.shape == oracle.effect.shape == (layout.size,)
        for name in layout.slices:
            a, b = layout.view(compiled.effect, name), layout.view(oracle.effect, name)
            assert np.all(np.isfinite(a)), name
            scale = np.max(np.abs(b))
            assert np.max(np.abs(a - b)) <= rtol * scale, ("effect", name, np.max(np.abs(a - b)) / scale)
    # the block's own group for the bound's jackknife: its count, its effect sums (compared above) and
    # its sum of e^2, the diagonal of error_outer (compared below)
    assert (compiled.effect_blocks is None) == (oracle.effect_blocks is None)
    if oracle.effect_blocks is not None:
        assert len(compiled.effect_blocks) == len(oracle.effect_blocks)
        assert sum(g[0] for g in oracle.effect_blocks) == oracle.count
        if len(oracle.effect_blocks) == 1:  # one block: its group is its own sums
            assert np.array_equal(compiled.effect_blocks[0][1], compiled.effect)
            assert np.array_equal(oracle.effect_blocks[0][1], oracle.effect)
            assert np.array_equal(oracle.effect_blocks[0][2], np.diagonal(oracle.error_outer, axis1=1, axis2=2))
        for (cn, ce, cm), (on, oe, om) in zip(compiled.effect_blocks, oracle.effect_blocks):
            assert cn == on
            assert np.max(np.abs(cm - om)) <= rtol * np.max(np.abs(om))
            for name in layout.slices:
                a, b = layout.view(ce, name), layout.view(oe, name)
                assert np.max(np.abs(a - b)) <= rtol * np.max(np.abs(b)), ("effect_blocks", name)
    for f in dataclasses.fields(oracle):
        if f.name in ("effect", "effect_blocks"):
            continue
        a, b = getattr(compiled, f.name), getattr(oracle, f.name)
        if f.name == "count":
            assert a == b
            continue
        assert (a is None) == (b is None), f.name
        if b is None:
            continue
        if f.name.endswith("_histogram"):  # the shape check's counts: equal count for count, every value binned
            assert np.array_equal(a, b), (f.name, np.abs(a - b).sum())
            assert np.all(b.sum(axis=1) == oracle.count), f.name
            continue
        assert a.shape == b.shape, f.name
        assert np.all(np.isfinite(a)), f.name
        scale = np.max(np.abs(b))
        assert np.max(np.abs(a - b)) <= rtol * scale, (f.name, np.max(np.abs(a - b)) / scale)


@pytest.mark.parametrize("n", [300, 64])  # 300: a full tile of 216 lanes and a last of 84; 64: one tile, not full
def test_range_bearing_compiled_block_sums_equal_the_numpy_path(n):
    problem = load_code_model(str(EXAMPLE), ["scenario.updates=12", "filter.compiled=yes"]).problem()
    assert problem.compiled_path == (True, "")
    compiled = problem._compiled_block_sums(block_generator(5, 0), n)
    assert compiled is not None  # the kernel ran (no fallback to the numpy path hides here)
    oracle = problem.numpy_block_sums(block_generator(5, 0), n, "exact")
    _assert_same_sums(compiled, oracle, layout=problem.layout)
    _assert_same_sums(problem.block_sums(block_generator(5, 0), n, "exact"), oracle, layout=problem.layout)
    assert (problem.tally.compiled, problem.tally.fallback, problem.tally.numpy) == (1, 0, 0)


def test_linear_model_with_another_truth_compiled_block_sums_equal_the_numpy_path():
    """A filter that believes R x 4 against its truth: two models, two sets of printed functions."""
    problem = load_code_model((_linear(1.0), _linear(4.0)), ["scenario.updates=7", "filter.compiled=yes"]).problem()
    assert problem.compiled_path[0]
    compiled = problem._compiled_block_sums(block_generator(2, 3), 150)
    assert compiled is not None  # the kernel ran
    oracle = problem.numpy_block_sums(block_generator(2, 3), 150, "exact")
    _assert_same_sums(compiled, oracle, layout=problem.layout)


@pytest.mark.parametrize("n", [300, 64, 2 * _TILE])  # the last: full tiles alone
def test_imu_3axis_compiled_block_sums_equal_the_numpy_path(n):
    """The checked hook (9 parameters of 11 states) in the kernel: the checks' sums on the 9, the bound's
    expectations on all 11 (its renewed tilts are marginalized from them afterwards, on either path)."""
    problem = build_scenario("imu-3axis", None, ["filter.kind=ekf", "filter.compiled=yes"]).problem()
    assert problem.compiled_path == (True, "")
    compiled = problem._compiled_block_sums(block_generator(5, 0), n)
    assert compiled is not None  # the kernel ran (no fallback to the numpy path hides here)
    oracle = problem.numpy_block_sums(block_generator(5, 0), n, "exact")
    assert compiled.error.shape == (12, 9) and compiled.effect.shape == oracle.effect.shape
    _assert_same_sums(compiled, oracle, layout=problem.layout)
    _assert_same_sums(problem.block_sums(block_generator(5, 0), n, "exact"), oracle, layout=problem.layout)


def test_the_threads_arena_is_overwritten_not_read():
    """The kernel's tile state lives in its thread's arena, kept from tile to tile and block to block (no
    page faults of fresh memory per block): what an earlier block or anything else left there (NaN here, or a larger
    arena's state) changes no sum, bit for bit; the arena grows where a larger one is asked for and is reused."""
    from kalcal.scenarios.nonlinear import problem as nonlinear_problem
    from kalcal.scenarios.nonlinear.kernel import arena_size

    problem = build_scenario("imu-3axis", None, ["filter.kind=ekf", "filter.compiled=yes"]).problem()
    n = _TILE + 84
    clean = nonlinear_problem._thread_arena(arena_size(11, 3, 9, _TILE))
    clean[:] = 0.0
    want = problem._compiled_block_sums(block_generator(5, 0), n)
    nonlinear_problem._thread_arena(arena_size(11, 3, 9, 3 * _TILE))[:] = np.nan  # grown, then poisoned
    dirty = nonlinear_problem._thread_arena(arena_size(11, 3, 9, _TILE))
    assert dirty.shape[0] >= arena_size(11, 3, 9, 3 * _TILE) and np.isnan(dirty).all()
    got = problem._compiled_block_sums(block_generator(5, 0), n)
    assert got is not None and nonlinear_problem._thread_arena(1) is dirty  # the same arena, reused
    _assert_same_sums(got, want, rtol=0.0, layout=problem.layout)
    assert _same_groups(got.effect_blocks, want.effect_blocks)


def _inputs_and_correlated_r() -> tuple[NonlinearModel, NonlinearModel, np.ndarray]:
    """A truth and a filter with known inputs u (accelerations, one row per update) and a correlated R, each
    measurement of one state (H sparse: R^-1/2 H's zeros are filled by R's correlation, the kernel's
    ``w_nz`` propagation; R's off-diagonal its ``r_cols``), and the filter's R not the truth's."""

    def f(x, u, dt):
        return xm.stack([x[:, 0] + dt * x[:, 2] + 0.5 * dt**2 * u[..., 0], x[:, 1] + dt * u[..., 1], x[:, 2] + dt * u[..., 0]])

    def h(x, data):
        return xm.stack([x[:, 0] + 0.05 * x[:, 0] * x[:, 0], xm.sin(x[:, 1])])

    common = dict(f=f, h=h, q=np.diag([0.01, 0.002, 0.001]), x0=[1.0, 0.3, 0.1], p0=np.diag([1.0, 0.04, 0.01]),
                  dt=1.0, state_names=("a", "b", "c"), state_units=("m", "rad", "m/s"), measurement_names=("y1", "y2"),
                  measurement_units=("m", "1"), input_dim=2)
    truth = NonlinearModel(r=np.array([[1.0, 0.6], [0.6, 1.0]]) * 1.5, **common)
    belief = NonlinearModel(r=np.array([[1.0, 0.6], [0.6, 1.0]]), **common)
    inputs = np.random.default_rng(0).normal(0.0, 0.05, (6, 2))
    return truth, belief, inputs


def test_known_inputs_and_a_correlated_r_compiled_block_sums_equal_the_numpy_path():
    """The kernel's paths for u (per update) and for R's off-diagonal (about a minute's compile on a cold cache)."""
    from kalcal.scenarios.nonlinear.settings import register_models

    truth, belief, inputs = _inputs_and_correlated_r()
    problem = load_code_model(register_models(truth, belief, inputs=inputs, n_updates=6), ["filter.compiled=yes"]).problem()
    assert problem.compiled_path == (True, "")
    compiled = problem._compiled_block_sums(block_generator(3, 0), 300)
    assert compiled is not None  # the kernel ran
    oracle = problem.numpy_block_sums(block_generator(3, 0), 300, "exact")
    _assert_same_sums(compiled, oracle, layout=problem.layout)
    # what the comparison holds is there: the inputs move the estimates (the same draws without them give
    # others), and R's correlation fills H^T R^-1 H's entry of two states no one measurement sees together
    still = load_code_model(register_models(truth, belief, inputs=np.zeros_like(inputs), n_updates=6),
                            ["filter.compiled=no"]).problem().numpy_block_sums(block_generator(3, 0), 300, "exact")
    assert np.max(np.abs(still.estimate - oracle.estimate)) > 1e-3 * np.max(np.abs(oracle.estimate))
    htrh = problem.layout.view(oracle.effect, "htrh")[0] / 300
    assert abs(htrh[0, 1]) > 1e-3 * np.max(np.abs(htrh))


def test_imu_3axis_paths_say_which_runs_and_why():
    def path(*settings):
        return build_scenario("imu-3axis", None, list(settings)).problem().compiled_path

    assert path("filter.kind=ekf", "filter.compiled=yes") == (True, "")
    assert path("filter.kind=ekf", "filter.compiled=no") == (False, "the numpy path was asked for (filter.compiled=no)")
    compiled, reason = path("filter.kind=batch", "filter.compiled=yes")
    assert not compiled and "batch estimator" in reason
    for kind in ("iekf", "ukf"):
        compiled, reason = path(f"filter.kind={kind}", "filter.compiled=yes")
        assert not compiled and kind.upper() in reason


def test_compiled_run_same_seed_same_sums_whatever_the_workers_and_the_numpy_runs():
    problem = load_code_model(str(EXAMPLE), ["scenario.updates=6", "filter.compiled=yes"]).problem()
    numpy_problem = load_code_model(str(EXAMPLE), ["scenario.updates=6", "filter.compiled=no"]).problem()
    assert numpy_problem.compiled_path == (False, "the numpy path was asked for (filter.compiled=no)")
    one = run_monte_carlo(problem, 9000, 11, workers=1).sums
    two = run_monte_carlo(problem, 9000, 11, workers=2).sums
    blocks = block_count(9000)
    # every block of both runs in the kernel: the comparisons below hold the kernel, not the numpy path twice
    assert (problem.tally.compiled, problem.tally.fallback, problem.tally.numpy) == (2 * blocks, 0, 0)
    assert blocks > 1
    for f in dataclasses.fields(one):
        a, b = getattr(one, f.name), getattr(two, f.name)
        if f.name == "effect_blocks":  # the bound's jackknife groups, block by block
            assert _same_groups(a, b), f.name
            continue
        assert (a is None and b is None) or np.array_equal(a, b), f.name
    _assert_same_sums(one, run_monte_carlo(numpy_problem, 9000, 11, workers=1).sums, layout=problem.layout)
    assert (numpy_problem.tally.compiled, numpy_problem.tally.numpy) == (0, blocks)


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
    of realization ``at`` at update 3); its state is the wrapped one's, so a path that restores it redraws the same."""

    def __init__(self, seed, at=5):
        self._rng = block_generator(seed, 0)
        self.bit_generator = self._rng.bit_generator
        self._at = at

    def standard_normal(self, shape):
        out = self._rng.standard_normal(shape)
        if len(shape) == 3:
            out[3, self._at, shape[2] - 1] = np.nan
        return out


@pytest.mark.parametrize("n, at", [(100, 5), (_TILE + 84, _TILE + 40)])  # in the first tile, or in a later one
def test_a_missing_measurement_stops_the_kernel_and_the_block_runs_on_the_numpy_path_from_the_same_draws(n, at):
    """The kernel stops at the NaN, in whichever tile (a later tile's stop leaves the earlier tiles' sums in
    buffers the caller drops), and the block's numbers are the numpy path's from the same draws."""
    problem = load_code_model(str(EXAMPLE), ["scenario.updates=6", "filter.compiled=yes"]).problem()
    assert problem.compiled_path[0]
    assert problem._compiled_block_sums(_PlantedNaN(4, at), n) is None  # the kernel stops at the NaN
    got = problem.block_sums(_PlantedNaN(4, at), n, "exact")
    assert (problem.tally.compiled, problem.tally.fallback) == (0, 1)  # counted as the fallback it was
    want = problem.numpy_block_sums(_PlantedNaN(4, at), n, "exact")
    for f in dataclasses.fields(want):
        a, b = getattr(got, f.name), getattr(want, f.name)
        if f.name == "effect_blocks":
            assert _same_groups(a, b, equal_nan=True), f.name
            continue
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
    problem = load_code_model(model, ["scenario.updates=4", "filter.compiled=yes"]).problem()
    assert problem.compiled_path[0]  # printed and imported: numba compiles at the first block
    got = problem.block_sums(block_generator(9, 0), 50, "exact")
    compiled, reason = problem.compiled_path
    assert not compiled and "numba cannot compile" in reason
    _assert_same_sums(got, problem.numpy_block_sums(block_generator(9, 0), 50, "exact"), rtol=0.0, layout=problem.layout)


def _unseen() -> NonlinearModel:
    """A model whose printed module no test compiles (its own h): its kernel is compiled nowhere."""
    m = _linear(1.0)
    return dataclasses.replace(m, h=lambda x, data: xm.stack([x[:, 0] + 0.25 * x[:, 2], x[:, 1] - 0.5 * x[:, 3]]))


def test_auto_compiles_only_a_run_that_repays_the_compile_and_yes_no_force(monkeypatch, tmp_path):
    """Nothing is compiled here: the decision is read before any block runs."""
    from kalcal.scenarios.nonlinear.problem import COMPILE_WORTH

    monkeypatch.setenv("KALCAL_CACHE_DIR", str(tmp_path))  # a cache of its own: no machine code in it
    model = _unseen()
    problem = load_code_model((model, model), ["scenario.updates=50"]).problem()
    assert problem.compiled == "auto"  # the default
    compiled, reason = problem.compiled_path
    assert not compiled and "filter.compiled=auto" in reason and "not compiled yet" in reason
    below = problem.plan(COMPILE_WORTH // 50 - 1)  # N K one short of the threshold
    compiled, reason = below.compiled_path
    assert not compiled and f"{COMPILE_WORTH // 50 - 1} realizations of 50 updates" in reason
    at = problem.plan(COMPILE_WORTH // 50)
    assert at.compiled_path == (True, "")
    assert at.plan(10).planned == COMPILE_WORTH // 50  # a plan only grows
    forced = load_code_model((model, model), ["scenario.updates=50", "filter.compiled=yes"]).problem()
    assert forced.compiled_path == (True, "")
    kept = load_code_model((model, model), ["scenario.updates=50", "filter.compiled=no"]).problem().plan(10**9)
    assert kept.compiled_path == (False, "the numpy path was asked for (filter.compiled=no)")
    # and the numpy path runs the block (no kernel compiled for it)
    assert problem.block_sums(block_generator(0, 0), 30, "exact").count == 30


def test_auto_runs_a_kernel_compiled_in_this_process_or_in_numbas_cache():
    forced = load_code_model(str(EXAMPLE), ["scenario.updates=5", "filter.compiled=yes"]).problem()
    forced.block_sums(block_generator(1, 0), 64, "exact")  # compiled (or loaded from the cache) here
    auto = load_code_model(str(EXAMPLE), ["scenario.updates=5"]).problem()
    assert auto.planned is None and auto.compiled_path == (True, "")
    # a new process finds it in numba's cache beside the generated module (KALCAL_CACHE_DIR, inherited)
    code = (
        "from kalcal.scenarios import load_code_model; "
        f"p = load_code_model({str(EXAMPLE)!r}, ['scenario.updates=5']).problem(); print(p.compiled_path)"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "(True, '')"


def test_filter_compiled_setting_is_refused_with_its_name(tmp_path):
    done = subprocess.run(
        [sys.executable, "-m", "kalcal", "verify", str(EXAMPLE), "-n", "200", "--out", str(tmp_path / "o"),
         "--set", "filter.compiled=maybe"],
        capture_output=True, text=True,
    )
    assert done.returncode == 2
    assert len(done.stderr.strip().splitlines()) == 1 and "filter.compiled" in done.stderr


@pytest.mark.parametrize("which", ["imu-3axis", "range-bearing"])
def test_printed_zero_patterns_cover_every_nonzero_jacobian_entry(which):
    """The printed F and H write only the entries their patterns name and the kernel skips the products
    with the others: every entry outside a pattern is zero at random states (a pattern that left out a
    nonzero entry would drop it from the filter), and the pose model's are the few ones they should be."""
    import ast

    from kalcal.core.nonlinear_codegen import model_source

    if which == "imu-3axis":
        loaded = build_scenario("imu-3axis", None, []).loaded
        model, data = loaded.filter, loaded.data[0]
    else:
        loaded = load_code_model(str(EXAMPLE), []).loaded
        model, data = loaded.filter, loaded.data if loaded.data.ndim == 1 else loaded.data[0]
    text = model_source(model, "m")
    patterns = {}
    for line in text.splitlines():
        if line.startswith(("m_F_nz = ", "m_H_nz = ")):
            name, value = line.split(" = ")
            patterns[name] = np.array(ast.literal_eval(value), dtype=bool)
    rng = np.random.default_rng(3)
    x = model.x0 + rng.standard_normal((50, model.state_dim)) @ np.linalg.cholesky(model.p0).T
    jf = np.asarray(model.transition_jacobian(x, None))
    jh = np.asarray(model.measurement_jacobian(x, data))
    assert np.all(jf[:, ~patterns["m_F_nz"]] == 0) and np.all(jh[:, ~patterns["m_H_nz"]] == 0)
    assert np.all(np.any(jf != 0, axis=0)[patterns["m_F_nz"]]) and np.all(np.any(jh != 0, axis=0)[patterns["m_H_nz"]])
    if which == "imu-3axis":
        assert np.array_equal(patterns["m_F_nz"], np.diag(np.r_[np.ones(9), 0, 0]).astype(bool))
        assert patterns["m_H_nz"].sum() == 15  # x: s_x, b_x, 2 tilts; y: + a0; z: + a1, a2


@pytest.mark.parametrize("compiled", ["yes", "no"])
def test_memory_is_flat_in_n_not_in_k(compiled):
    """docs/nonlinear.md's memory: every sum's size is the same whatever the block's n, and the whiteness
    check's pair sums are (K p)^2 floats, growing with K (as the block's normals (K, n, d + p) do)."""

    def sizes(updates, n):
        problem = load_code_model(str(EXAMPLE), [f"scenario.updates={updates}", f"filter.compiled={compiled}"]).problem()
        sums = problem.block_sums(block_generator(0, 0), n, "exact")
        return {f.name: getattr(sums, f.name).shape for f in dataclasses.fields(sums)
                if isinstance(getattr(sums, f.name), np.ndarray)}

    assert sizes(6, 40) == sizes(6, 130)  # flat in n
    assert sizes(6, 40)["residual_outer"] == (12, 12) and sizes(12, 40)["residual_outer"] == (24, 24)


@pytest.mark.slow  # a new model's kernel: about a minute's compile on a cold cache
@pytest.mark.parametrize("checked", [None, (0, 3), (0, 1, 3), (2,), (1,)])
def test_the_update_s_kept_states_and_m_s_zeros_hold_where_q_couples_a_renewed_state(checked):
    """The kernel derives which states the update keeps (F's columns that are not identically zero, and the
    checked states) and where M is identically zero (F's zero pattern and Q) from the model; imu-3axis's
    block-diagonal Q and F rows of I or 0 do not exercise the rest: here a random walk a, a state b renewed at
    each update whose process noise is correlated with a's (Q_ab != 0), a state c that copies a (its F row is
    not zero, its F column is: nothing reads it but h), a static d; p = 3 (the general update). Whatever states
    are checked, a renewed one among them, the compiled sums equal the numpy path's."""
    from kalcal.scenarios.nonlinear.problem import NonlinearProblem, ProblemHooks
    from kalcal.scenarios.nonlinear.settings import register_models

    def f(x, u, dt):
        return xm.stack([x[:, 0], 0.1 + 0.0 * x[:, 1], x[:, 0], x[:, 3]])

    def h(x, data):
        return xm.stack([x[:, 0] + 0.3 * xm.sin(x[:, 1]) * x[:, 3], x[:, 1] + 0.1 * x[:, 0] * x[:, 0], x[:, 3] + 0.5 * x[:, 2]])

    q = np.zeros((4, 4))
    q[0, 0], q[1, 1], q[0, 1], q[1, 0] = 0.01, 0.04, 0.015, 0.015
    model = NonlinearModel(f=f, h=h, q=q, r=np.diag([0.01, 0.02, 0.01]), x0=[1.0, 0.1, 1.0, 0.5],
                           p0=np.diag([0.2, 0.04, 0.2, 0.1]), dt=1.0, state_names=("a", "b", "c", "d"),
                           state_units=("1",) * 4, measurement_names=("y1", "y2", "y3"), measurement_units=("1",) * 3)
    scenario = load_code_model(register_models(model, model, n_updates=8), ["filter.compiled=yes"])

    class Hooked:  # the scenario with the checked states as its hooks
        problem_hooks = ProblemHooks(checked=checked)

        def __getattr__(self, name):
            return getattr(scenario, name)

    problem = NonlinearProblem(Hooked(), compiled="yes")
    compiled = problem._compiled_block_sums(block_generator(3, 0), 300)
    assert compiled is not None  # the kernel ran
    _assert_same_sums(compiled, problem.numpy_block_sums(block_generator(3, 0), 300, "exact"), layout=problem.layout)
