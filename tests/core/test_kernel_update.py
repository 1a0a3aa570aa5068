"""The one compiled covariance update against the numpy reference step, update by update.

Oracle: :func:`kalcal.core.steps.gain_and_covariance` (Joseph and standard forms) on each
realization of a tile, and :func:`kalcal.core.missing.measured` for the compiled missing-measurement
rule. The inputs are random SPD priors, random measurement matrices (a full p x d H, a regressor row that
differs per realization as the time-varying regressors of the scale-bias filter, and a scalar
measurement of one state) and random SPD noise; the rounding bound is relative to the reference's scale.
"""

from __future__ import annotations

import numpy as np
import pytest

from kalcal.core.kernels import covariance_update, measured, update_work
from kalcal.core.missing import measured as measured_reference
from kalcal.core.steps import gain_and_covariance


def _spd(rng, d, n=None):
    a = rng.standard_normal((d, d) if n is None else (n, d, d))
    return a @ np.swapaxes(a, -1, -2) + 0.1 * np.eye(d)


def _tile(array):
    """(m, ...) realizations first, to the kernel's (..., m) layout."""
    return np.ascontiguousarray(np.moveaxis(array, 0, -1))


CASES = {
    "full H, p = 2": (3, 2, "shared"),
    "full H, p = 3 of d = 4": (4, 3, "shared"),
    "time-varying row, p = 1": (2, 1, "per realization"),
    "scalar measurement of one state": (3, 1, "unit"),
}


@pytest.mark.parametrize("form", ["joseph", "standard"])
@pytest.mark.parametrize("case", sorted(CASES))
def test_compiled_update_equals_the_reference_step_for_every_realization(case, form):
    d, p, kind = CASES[case]
    rng = np.random.default_rng(sum(map(ord, case + form)))
    m = 7
    prior = _spd(rng, d, m)
    if kind == "shared":
        h = np.broadcast_to(rng.standard_normal((p, d)), (m, p, d)).copy()
    elif kind == "per realization":  # h_k = [z_k, 1], z_k different in every realization
        h = np.stack([1.0 + rng.standard_normal((m, 1)), np.ones((m, 1))], axis=-1)
    else:
        h = np.zeros((m, 1, d))
        h[:, 0, 1] = 1.0
    v = _spd(rng, p)
    gain, s, cov = np.empty((p, d, m)), np.empty((p, p, m)), _tile(prior)
    covariance_update(cov, _tile(h), v, form == "joseph", gain, s, update_work(d, p, m))
    want_gain, want_cov, want_s = gain_and_covariance(prior, h, v, form)
    for name, got, want in (("K^T", gain, np.swapaxes(want_gain, -1, -2)), ("P", cov, want_cov), ("S", s, want_s)):
        got = np.moveaxis(got, -1, 0)
        scale = np.abs(want).max()
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-13 * scale, err_msg=name)
    np.testing.assert_array_equal(cov, np.swapaxes(cov, 0, 1))  # P symmetric exactly


def test_the_joseph_form_keeps_a_precise_measurement_s_variance_where_the_standard_form_cancels():
    """Not a tautology of the comparison above: the two forms differ in rounding. With a very precise
    measurement of one state (V = 1e-12 against M ~ 1e4), the exact posterior variance of that state is
    V M_00 / (M_00 + V); the standard form's M - K H M cancels it to rounding (about 1e4 eps = 2e-12, as
    large as the value), the Joseph form keeps it to a relative 1e-6 and P positive definite."""
    rng = np.random.default_rng(4)
    d, m = 3, 50
    prior = _spd(rng, d, m) * 1e4
    h = np.zeros((m, 1, d))
    h[:, 0, 0] = 1.0
    v = np.array([[1e-12]])
    cov = _tile(prior)
    covariance_update(cov, _tile(h), v, True, np.empty((1, d, m)), np.empty((1, 1, m)), update_work(d, 1, m))
    exact = v[0, 0] * prior[:, 0, 0] / (prior[:, 0, 0] + v[0, 0])
    np.testing.assert_allclose(cov[0, 0], exact, rtol=1e-6)
    assert np.linalg.eigvalsh(np.moveaxis(cov, -1, 0)).min() > 0.0


def test_compiled_missing_rule_equals_the_reference_rule_component_by_component():
    rng = np.random.default_rng(9)
    for _ in range(200):
        p, d = rng.integers(1, 4), rng.integers(1, 4)
        z, h = rng.standard_normal(p), rng.standard_normal((p, d))
        if rng.random() < 0.5:
            z[rng.integers(p)] = rng.choice([np.nan, np.inf])
        if rng.random() < 0.3:
            h[rng.integers(p), rng.integers(d)] = np.nan
        assert measured(z, h) == bool(measured_reference(z, h))


@pytest.mark.parametrize("p", [2, 3])
def test_the_joseph_form_keeps_precise_measurements_variances_with_several_components(p):
    """The same where p > 1 (its own code path: a Cholesky factor of S): p components each measure one state
    with V = 1e-12 I against M ~ 1e4. The exact posterior covariance of the measured block is
    V - V (M_mm + V)^-1 V (no cancellation: the correction is 1e-16 of V); the update keeps it to a relative
    1e-6 and P positive definite (as a correlation matrix). The algebraically equal expansion M - (H M)^T K^T + K (S K^T - H M) sums
    terms of M's size and gives that block at M's rounding (about 2e-12, as large as the value, or 0)."""
    rng = np.random.default_rng(40 + p)
    d, m = 4, 50
    prior = _spd(rng, d, m) * 1e4
    h = np.zeros((m, p, d))
    h[:, np.arange(p), np.arange(p)] = 1.0
    v = 1e-12 * np.eye(p)
    cov = _tile(prior)
    covariance_update(cov, _tile(h), v, True, np.empty((p, d, m)), np.empty((p, p, m)), update_work(d, p, m))
    block = prior[:, :p, :p]
    exact = v - v @ np.linalg.solve(block + v, np.broadcast_to(v, block.shape))
    got = np.moveaxis(cov, -1, 0)
    np.testing.assert_allclose(got[:, :p, :p], exact, rtol=1e-6, atol=1e-6 * 1e-12)
    # positive definite as a correlation matrix (P's variances span 1e-12 to 1e4: its eigenvalues below
    # about 1e4 eps are below eigvalsh's rounding)
    scale = np.sqrt(np.einsum("nii->ni", got))
    assert np.linalg.eigvalsh(got / (scale[:, :, None] * scale[:, None, :])).min() > 0.0


@pytest.mark.parametrize("form", ["joseph", "standard"])
def test_the_update_with_m_s_zeros_and_kept_states_gives_the_kept_entries_of_the_whole_update_bit_for_bit(form):
    """``UpdateWork.m_nz`` and ``keep`` (a caller's M with a renewed state's zeros, P read on some states
    alone): H M skips the products with M's identically zero entries, the update computes the kept states'
    rows of K and entries of P alone. Those and S are the whole update's bit for bit (a skipped product is
    an exact zero), P's others keep M's values; and the kept entries equal the reference step's."""
    rng = np.random.default_rng(41)
    d, p, m = 6, 3, 9
    renewed = [4, 5]  # no covariance with the others (a renewed state's M row is Q's)
    prior = _spd(rng, d, m)
    prior[:, :4, 4:] = 0.0
    prior[:, 4:, :4] = 0.0
    h = rng.standard_normal((m, p, d))
    h_nz = rng.random((p, d)) < 0.7
    h_nz[:, renewed] = True  # the renewed states measured, as a pose's tilts are
    h = h * h_nz
    v = _spd(rng, p)
    keep = np.ones(d, dtype=bool)
    keep[renewed] = False
    m_nz = np.abs(prior).max(axis=0) != 0.0
    out = {}
    for name in ("whole", "masked"):
        work = update_work(d, p, m)
        work.h_nz[:, :] = h_nz
        if name == "masked":
            work.m_nz[:, :] = m_nz
            work.keep[:] = keep
        gain, s, cov = np.empty((p, d, m)), np.empty((p, p, m)), _tile(prior)
        covariance_update(cov, _tile(h), v, form == "joseph", gain, s, work)
        out[name] = gain, s, cov
    (gain_w, s_w, cov_w), (gain_m, s_m, cov_m) = out["whole"], out["masked"]
    np.testing.assert_array_equal(gain_m[:, keep], gain_w[:, keep])
    np.testing.assert_array_equal(s_m, s_w)
    kept = np.ix_(keep, keep)
    np.testing.assert_array_equal(cov_m[kept], cov_w[kept])
    np.testing.assert_array_equal(cov_m[renewed], _tile(prior)[renewed])  # M's values, not P's
    np.testing.assert_array_equal(cov_m[:, renewed], _tile(prior)[:, renewed])
    assert not np.array_equal(cov_w[renewed], _tile(prior)[renewed])  # the whole update does change them
    want_gain, want_cov, _ = gain_and_covariance(prior, h, v, form)
    np.testing.assert_allclose(np.moveaxis(gain_m, -1, 0)[:, :, keep], np.swapaxes(want_gain, -1, -2)[:, :, keep],
                               rtol=1e-12, atol=1e-13 * np.abs(want_gain).max())
    got = np.moveaxis(cov_m, -1, 0)[:, keep][:, :, keep]
    np.testing.assert_allclose(got, want_cov[:, keep][:, :, keep], rtol=1e-12, atol=1e-13 * np.abs(want_cov).max())
