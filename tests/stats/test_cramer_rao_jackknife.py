"""The Cramér–Rao bound's own Monte Carlo error: the delete-one-group jackknife over the engine's independent
blocks (:func:`kalcal.stats.effects.cramer_rao_bound`). Fixed seeds; bounds from theory (chi-square, F)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import stats as sps

from kalcal.core import xmath as xm
from kalcal.core.nonlinear import NonlinearModel, load_nonlinear_model
from kalcal.montecarlo import checkpoint
from kalcal.montecarlo.accumulators import EFFECT_GROUPS_MAX, merge_effect_blocks
from kalcal.montecarlo.engine import run_monte_carlo
from kalcal.scenarios import load_code_model
from kalcal.stats.effects import BELOW_BOUND_ERROR, BELOW_BOUND_ERROR_MSE_ONLY, CramerRaoBound

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "range_bearing.py"
rb = load_nonlinear_model(EXAMPLE)


def _linear_model() -> NonlinearModel:
    """The range-bearing model's constant-velocity f with a linear h: F and H do not depend on the state."""
    m = rb.filter
    return NonlinearModel(
        f=m.f, h=lambda x, data: xm.stack([x[:, 0] + 0.5 * x[:, 2], x[:, 1]]), q=m.q, r=np.diag([1.0, 4.0]),
        x0=m.x0, p0=m.p0, dt=1.0, state_names=m.state_names, state_units=m.state_units,
        measurement_names=("a", "b"), measurement_units=("m", "m"),
    )


def _bound(scenario, n, seed, block_size, workers=1):
    problem = scenario.problem()
    run = run_monte_carlo(problem, n, seed, workers=workers, block_size=block_size)
    return run, problem.effect_sizes(run.sums, 0.99).cramer_rao


def test_linear_model_bound_has_no_monte_carlo_error():
    """Where F and H are constant the expectations do not depend on the states: every leave-one-group-out
    bound is the same Riccati P, and the jackknife's standard error vanishes to rounding; the MSE's does
    not, and the jackknife of MSE - bound is then the jackknife of the MSE alone, an estimate of mse_se with
    G - 1 = 19 degrees of freedom: (G - 1) se_jack^2 / mse_se^2 within chi-square(19)'s 0.0005 and 0.9995
    quantiles per state (Bonferroni over the 4 states: a correct jackknife fails with probability <= 0.004;
    mse_se itself, from 4000 realizations, is exact by comparison)."""
    run, crb = _bound(load_code_model(_linear_model(), ["scenario.updates=15"]), 4000, 5, 200)
    assert crb.groups == 20
    bound = np.diagonal(crb.bound, axis1=1, axis2=2)
    assert crb.bound_se.shape == bound.shape
    assert np.all(crb.bound_se <= 1e-10 * bound)
    ratio = (crb.groups - 1) * crb.difference_se**2 / crb.mse_se[-1] ** 2
    chi2 = sps.chi2(crb.groups - 1)
    assert np.all((chi2.ppf(0.0005) <= ratio) & (ratio <= chi2.isf(0.0005))), ratio


@pytest.mark.parametrize("updates", [20, pytest.param(100, marks=pytest.mark.slow)])
def test_range_bearing_jackknife_agrees_with_the_spread_over_seeds(updates):
    """R = 20 independent seeds of the range-bearing EKF (2000 realizations, 10 blocks of 200, K = 20, and
    the example's K = 100 among the slow tests): the
    sample variance s^2 of each state's final bound over the seeds estimates its Monte Carlo variance
    sigma^2 with R - 1 = 19 degrees of freedom ((R - 1) s^2 / sigma^2 ~ chi-square(19)); the jackknife's
    variance, averaged over the seeds, estimates it with about R (G - 1) = 180 (each seed's about
    sigma^2 chi-square(G - 1) / (G - 1), the jackknife of a smooth function of G independent group means).
    Their ratio is then about F(19, 180): within its 0.000625 and 0.999375 quantiles per state (Bonferroni
    over 4 states at 0.005 in all). A jackknife off by the factor G (the mean's error, not a sum's) or
    missing its (G - 1) / G would fail it."""
    scenario = load_code_model(str(EXAMPLE), [f"scenario.updates={updates}"])
    bounds, variances = [], []
    for seed in range(20):
        _, crb = _bound(scenario, 2000, 100 + seed, 200)
        assert crb.groups == 10
        bounds.append(np.diagonal(crb.bound[-1]))
        variances.append(crb.bound_se[-1] ** 2)
    spread = np.var(np.array(bounds), axis=0, ddof=1)
    jack = np.mean(np.array(variances), axis=0)
    assert np.all(jack > 0)
    ratio = spread / jack
    f = sps.f(19, 180)
    assert np.all((f.ppf(0.000625) <= ratio) & (ratio <= f.isf(0.000625))), ratio


@pytest.mark.parametrize("n, block_size", [(3000, 500), (6500, 100)])
def test_same_seed_same_jackknife_whatever_the_threads(n, block_size):
    """1 and 2 threads merge in block order: the same groups, the same standard errors bit for bit (6500 /
    100 is 65 blocks, one past the cap: folded in adjacent pairs into 32 groups of 200 and the last block)."""
    scenario = load_code_model(str(EXAMPLE), ["scenario.updates=10"])
    one_run, one = _bound(scenario, n, 7, block_size, workers=1)
    two_run, two = _bound(scenario, n, 7, block_size, workers=2)
    blocks = -(-n // block_size)
    assert one.groups == two.groups == (blocks if blocks <= EFFECT_GROUPS_MAX else EFFECT_GROUPS_MAX // 2 + 1)
    assert [g[0] for g in two_run.sums.effect_blocks] == [g[0] for g in one_run.sums.effect_blocks]
    np.testing.assert_array_equal(one.bound_se, two.bound_se)
    np.testing.assert_array_equal(one.difference_se, two.difference_se)
    groups = one_run.sums.effect_blocks
    assert sum(g[0] for g in groups) == n
    total = one_run.sums.effect
    np.testing.assert_allclose(sum(g[1] for g in groups), total, rtol=1e-12, atol=1e-12 * np.max(np.abs(total)))


def test_groups_fold_in_pairs_past_the_cap_keeping_block_order():
    blocks = tuple((1, np.array([float(i)]), np.array([[float(i)]])) for i in range(EFFECT_GROUPS_MAX + 1))
    merged = merge_effect_blocks(blocks[:EFFECT_GROUPS_MAX], blocks[EFFECT_GROUPS_MAX:])
    assert len(merged) == EFFECT_GROUPS_MAX // 2 + 1
    assert [g[0] for g in merged] == [2] * (EFFECT_GROUPS_MAX // 2) + [1]
    assert [float(g[1][0]) for g in merged] == [2.0 * i + 1.0 for i in range(0, EFFECT_GROUPS_MAX, 2)] + [EFFECT_GROUPS_MAX]
    assert merge_effect_blocks(blocks[:2], None) is None


def test_checkpoint_keeps_the_groups_and_one_without_them_reports_no_bound_error(tmp_path):
    scenario = load_code_model(str(EXAMPLE), ["scenario.updates=10"])
    problem = scenario.problem()
    run = run_monte_carlo(problem, 1200, 3, block_size=400)
    path = tmp_path / "c.npz"
    checkpoint.save(path, run.sums, 3, "x")
    loaded, _ = checkpoint.load(path, "x")
    assert len(loaded.effect_blocks) == 3
    for (a, b, c), (x, y, z) in zip(loaded.effect_blocks, run.sums.effect_blocks):
        assert a == x and np.array_equal(b, y) and np.array_equal(c, z)
    # a checkpoint written before the groups were kept: the same sums, the bound, no error of its own
    with np.load(path) as data:
        older = {k: data[k] for k in data.files if not k.startswith("effect_blocks")}
    np.savez(path, **older)
    loaded, _ = checkpoint.load(path, "x")
    assert loaded.effect_blocks is None
    crb = problem.effect_sizes(loaded, 0.99).cramer_rao
    assert crb.available and crb.bound_se is None and crb.difference_se is None
    rows = crb.per_state(("px", "py", "vx", "vy"), ("m", "m", "m/s", "m/s"), 0.99)
    assert all(r["lower_bound_se"] is None and r["below_bound_error"] == BELOW_BOUND_ERROR_MSE_ONLY for r in rows)


def _constructed(bound: float, difference_se) -> CramerRaoBound:
    """One state at one update: MSE 1.0 +- 0.01, the bound given, its jackknife errors given (or None)."""
    return CramerRaoBound(
        True, "constructed", np.array([[[bound]]]), np.array([[1.0]]), np.array([[0.01]]),
        None if difference_se is None else np.array([[0.03]]), None if difference_se is None else np.array([difference_se]), 8,
    )


def test_below_bound_counts_the_error_of_the_difference():
    """z = 2.576 and t(7) = 3.499 at 0.99 (8 groups). MSE 1.0 +- 0.01 against a bound 1.05: below beyond
    the MSE's error alone (1.0 + 2.576 x 0.01 < 1.05), not beyond the difference's 0.04 (-0.05 + 3.499 x
    0.04 > 0); against a bound 1.2, below beyond both (-0.2 + 0.140 < 0). A difference's error of 0.015
    against the bound 1.05 tells the t quantile from the normal one: -0.05 + 2.576 x 0.015 < 0 but
    -0.05 + 3.499 x 0.015 > 0, not below (the jackknife's error, from 8 groups, is itself uncertain)."""
    row = _constructed(1.05, 0.04).per_state(("a",), ("m",), 0.99)[0]
    assert row["below_bound"] is False and row["lower_bound_se"] == 0.03 and row["difference_se"] == 0.04
    assert row["below_bound_error"] == BELOW_BOUND_ERROR
    alone = _constructed(1.05, None).per_state(("a",), ("m",), 0.99)[0]
    assert alone["below_bound"] is True and alone["lower_bound_se"] is None
    assert alone["below_bound_error"] == BELOW_BOUND_ERROR_MSE_ONLY
    assert _constructed(1.2, 0.04).per_state(("a",), ("m",), 0.99)[0]["below_bound"] is True
    assert _constructed(1.05, 0.015).per_state(("a",), ("m",), 0.99)[0]["below_bound"] is False


def test_summary_typed_results_and_report_carry_the_bounds_error(tmp_path, monkeypatch):
    """9000 realizations are 3 blocks of the engine (4096, 4096, 808): summary.json's rows, the typed
    results and the report carry the bound's own error, equal to the jackknife's from the same sums."""
    import shutil

    import kalcal

    shutil.copytree(ROOT / "examples", tmp_path / "examples")
    monkeypatch.chdir(tmp_path)
    result = kalcal.verify(
        "examples/range_bearing.py", n=9000, seed=4, long_run=0, out=tmp_path / "out",
        settings={"scenario.updates": 10, "checks.power_runs": 0}, report=True,
    )
    crb = result.raw_summary["cramer_rao"]
    assert crb["jackknife_groups"] == 3 and len(crb["bound_diagonal_se"]) == 10
    for row in crb["final"]:
        assert row["lower_bound_se"] > 0 and row["difference_se"] > 0 and row["below_bound_error"] == BELOW_BOUND_ERROR
        assert row["lower_bound_se"] == pytest.approx(crb["bound_diagonal_se"][-1][crb["final"].index(row)], rel=0, abs=0)
    typed = result.cramer_rao
    assert typed.jackknife_groups == 3 and typed.state("px").lower_bound_se == crb["final"][0]["lower_bound_se"]
    np.testing.assert_array_equal(typed.bound_diagonal_se, np.array(crb["bound_diagonal_se"]))
    page = (tmp_path / "out" / "report.html").read_text()
    from kalcal.stats.text import fmt

    bound, se = crb["final"][0]["lower_bound"], crb["final"][0]["lower_bound_se"]
    assert f"{fmt(bound)} &plusmn; {fmt(se)}" in page


# The engine merges one block at a time in block order: whatever the number of blocks, every group but the
# last holds the same number of realizations (the plain delete-a-group formula's equal groups), the groups
# are contiguous runs of blocks in order, and there are at most EFFECT_GROUPS_MAX of them. (Folding pairs from
# the first group on, block after block, once left the first group holding almost every block: at 2,442
# blocks 832 of 1,000 in one group, the jackknife's variance 10 times too large.)
@pytest.mark.parametrize("blocks", [25, 64, 65, 129, 245, 1000, 2442])
def test_groups_stay_equal_and_in_order_whatever_the_number_of_blocks(blocks):
    groups = None
    for b in range(blocks):
        count = 4096 if b < blocks - 1 else 1000  # the last block is short
        marker = np.zeros(blocks)
        marker[b] = 1.0
        block = ((count, marker, np.zeros((1, 1))),)
        groups = block if groups is None else merge_effect_blocks(groups, block)
    sizes = [g[0] for g in groups]
    assert len(groups) <= EFFECT_GROUPS_MAX and len(set(sizes[:-1])) <= 1 and sizes[-1] <= sizes[0], sizes
    assert sum(sizes) == 4096 * (blocks - 1) + 1000
    members = [np.flatnonzero(g[1]) for g in groups]
    assert np.array_equal(np.concatenate(members), np.arange(blocks))  # every block once, in order
    assert all(np.array_equal(m, np.arange(m[0], m[-1] + 1)) for m in members)  # each group a run of blocks
    if blocks > EFFECT_GROUPS_MAX:
        assert len(groups) > EFFECT_GROUPS_MAX // 2  # folding keeps between 32 and 64 groups
