"""The one compiled accumulation of the moment sums against their numpy definition, ``MomentSums.from_block``."""

from __future__ import annotations

from dataclasses import fields

import numpy as np
import pytest

from kalcal.montecarlo.accumulators import BlockResult, MomentSums, SumBuffers, _normalized, whiten
from kalcal.montecarlo.sum_kernels import accumulate


def _block(rng, n, n_updates, d, p) -> BlockResult:
    """Random errors, estimates and innovations with each realization's own SPD P_k (and, for p > 1, its
    normalized innovations, here any numbers: the sums only carry them)."""
    factor = rng.standard_normal((n, n_updates, d, d))
    cov = factor @ np.swapaxes(factor, -1, -2) + np.eye(d)
    residual = rng.standard_normal((n, n_updates, p))
    return BlockResult(
        error=rng.standard_normal((n, n_updates, d)),
        estimate=3.0 + rng.standard_normal((n, n_updates, d)),
        residual=residual,
        nees=rng.chisquare(d, (n, n_updates)),
        nis=rng.chisquare(p, (n, n_updates)),
        filter_cov_sum=cov.sum(axis=0),
        filter_cov=cov,
        normalized_residual=None if p == 1 else 0.5 * residual,
    )


def _compiled(block: BlockResult, tiles: list[int], own: bool, pairs: bool) -> MomentSums:
    """The sums of ``block`` by ``accumulate``, update by update, over the realizations in ``tiles``."""
    n, n_updates, d = block.error.shape
    p = block.residual.shape[2]
    sums = SumBuffers.zeros(n_updates, d, p, n, pairs, own_cov=own)
    white = whiten(block.filter_cov, block.error)
    # where P_k is each realization's own, the pairs are those of the normalized innovations (stored
    # by the kernel itself, as the regression kernel does)
    stored = _normalized(block) if own else block.residual

    def soa(a, first, m):  # (n, ...) of one update -> (..., m), realizations last and contiguous
        return np.ascontiguousarray(np.moveaxis(a[first:first + m], 0, -1))

    for k in range(n_updates):
        first = 0
        for m in tiles:
            empty = np.empty(0)
            accumulate(
                k,
                first,
                soa(block.error[:, k], first, m),
                soa(block.estimate[:, k], first, m),
                soa(block.residual[:, k], first, m),
                soa(block.nees[:, k], first, m) if own else empty,
                soa(block.nis[:, k], first, m) if own else empty,
                soa(block.filter_cov[:, k], first, m) if own else np.empty((0, 0, 0)),
                soa(white[:, k], first, m) if own else np.empty((0, m)),
                sums,
                False,
            )
            if pairs:
                sums.residuals[k * p:(k + 1) * p, first:first + m] = soa(stored[:, k], first, m)
            first += m
    assert first == n
    normalized = None if block.normalized_residual is None else block.normalized_residual.sum(axis=0)
    return MomentSums.from_buffers(n, sums, normalized)


@pytest.mark.parametrize("d, p", [(2, 1), (3, 2)])
@pytest.mark.parametrize("tiles", [[37], [16, 16, 5]])
def test_accumulate_equals_from_block(d, p, tiles):
    block = _block(np.random.default_rng(4), sum(tiles), 6, d, p)
    reference = MomentSums.from_block(block)
    compiled = _compiled(block, tiles, own=True, pairs=True)
    assert compiled.count == reference.count
    for f in fields(MomentSums):
        if f.name == "count":
            continue
        expected, got = getattr(reference, f.name), getattr(compiled, f.name)
        if expected is None:
            assert got is None, f.name
            continue
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12 * np.abs(expected).max(), err_msg=f.name)
    # the symmetric sums are symmetric bit for bit (the lower triangle is a copy)
    for name in ("error_outer", "estimate_outer", "filter_cov", "whitened_outer"):
        value = getattr(compiled, name)
        assert np.array_equal(value, np.swapaxes(value, 1, 2)), name


def test_shared_covariance_leaves_nees_nis_and_p_to_the_caller():
    """With empty per-realization arrays (fixed gains) the NEES, NIS and P sums stay zero; the rest is the same."""
    block = _block(np.random.default_rng(5), 40, 4, 3, 2)
    own = _compiled(block, [40], own=True, pairs=False)
    shared = _compiled(block, [40], own=False, pairs=False)
    assert own.residual_outer is None and shared.residual_outer is None
    for name in ("nees", "nis", "filter_cov"):
        assert not np.any(getattr(shared, name)), name
    assert shared.whitened_error is None and shared.whitened_outer is None and shared.whitened_estimate is None
    for name in ("error", "error_outer", "estimate", "estimate_outer", "error_estimate", "residual", "residual_own"):
        assert np.array_equal(getattr(own, name), getattr(shared, name)), name


def test_zero_buffers_and_the_pairs():
    sums = SumBuffers.zeros(5, 3, 2, 7, residual_pairs=True)
    assert sums.residuals.shape == (10, 7)
    assert sums.error_outer.shape == (5, 3, 3) and sums.residual_own.shape == (5, 2, 2) and sums.nees.shape == (5,)
    assert all(not np.any(a) for name, a in sums._asdict().items() if name not in ("residuals", "nees_grid", "nis_grid"))
    assert SumBuffers.zeros(5, 3, 2, 7, residual_pairs=False).residuals.shape == (0, 7)
    assert sums.whitened_error.shape == (0, 3) and sums.whitened_outer.shape == (0, 3, 3)
    own = SumBuffers.zeros(5, 3, 2, 7, residual_pairs=False, own_cov=True)
    assert own.whitened_error.shape == (5, 3) and own.whitened_estimate.shape == (5, 3, 3)
    # every sum a kernel adds into is a field of MomentSums; the pair sums come from ``residuals`` by syrk, and
    # ``effect`` (the effect sizes' sums) is added in numpy by the problems whose P is data-dependent, and
    # ``effect_blocks`` (its groups of blocks, for the bound's jackknife) is kept beside it
    kernel_sums = {f.name for f in fields(MomentSums)} - {"count", "residual_outer", "normalized_residual", "effect", "effect_blocks"}
    assert set(SumBuffers._fields) == kernel_sums | {"residuals", "nees_grid", "nis_grid"}



@pytest.mark.parametrize(("width", "n"), [(300, 4096), (300, 3616), (150, 4096), (30, 17), (2, 1), (301, 4096), (5, 100)])
def test_the_pair_sums_are_within_the_dot_product_bound_of_the_exact_sums_and_of_dsyrk(width, n):
    """Each pair sum is within gamma_n sum_i |a_i b_i| of the exact one (gamma_n = n u / (1 - n u), u =
    2^-53: the bound of any order of summation), the exact one computed in extended precision, and so within
    twice that of scipy's dsyrk (another BLAS build, an independent oracle); for odd and even widths K p and
    any block size, on the engine's one BLAS thread. The same bits wherever the buffer lies in memory."""
    from scipy.linalg.blas import dsyrk
    from threadpoolctl import threadpool_limits

    from kalcal.montecarlo.accumulators import ResidualProducts

    stacked = np.random.default_rng(width).standard_normal((width, n))
    moved = np.empty(width * n + 1)[1:].reshape(width, n)  # the same values, 8 bytes off the allocation
    moved[...] = stacked
    with threadpool_limits(1, "blas"):
        sums = ResidualProducts.upper(stacked)
        again = ResidualProducts.upper(moved)
        oracle = np.triu(dsyrk(1.0, stacked.T, trans=1, lower=0))
    assert np.array_equal(sums, again)
    upper = np.triu(np.ones((width, width), dtype=bool))
    assert np.all(sums[~upper] == 0.0) and np.all(oracle[~upper] == 0.0)
    extended = stacked.astype(np.longdouble)
    exact = (extended @ extended.T)[upper]
    scale = (np.abs(stacked) @ np.abs(stacked).T)[upper]
    u = 2.0**-53
    gamma = n * u / (1 - n * u) + n * float(np.finfo(np.longdouble).eps)  # and the reference's own rounding
    assert np.all(np.abs(sums[upper] - exact) <= gamma * scale)
    assert np.all(np.abs(sums[upper] - oracle[upper]) <= 2 * gamma * scale)
