"""The information filter's diffuse start: the numpy reference against its definition, the compiled twin against it."""

from __future__ import annotations

import numpy as np
import pytest

from kalcal.core import kernels
from kalcal.core.diffuse import DIFFUSE_RCOND, diffuse_start
from kalcal.core.steps import predict, update


def _series(n=40, d=2, seed=3):
    rng = np.random.default_rng(seed)
    h = np.column_stack([rng.normal(size=(n, d - 1)), np.ones(n)])
    y = h @ rng.normal(size=d) + 0.1 * rng.normal(size=n)
    return y, h


def _compiled(y, h, r, q):
    d = h.shape[1]
    x, cov = np.full(d, np.nan), np.full((d, d), np.nan)
    m = kernels.diffuse_start(np.ascontiguousarray(y), np.ascontiguousarray(h), r, np.ascontiguousarray(q), DIFFUSE_RCOND, x, cov)
    return m, x, cov


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("drift", [0.0, 0.05])
@pytest.mark.parametrize("missing", [False, True])
def test_compiled_start_equals_the_reference(d, drift, missing):
    y, h = _series(d=d)
    if missing:  # a missing value in the start: a prediction only in both
        y[1] = np.nan
        h[3, 0] = np.nan
    q = drift**2 * np.eye(d)
    ref = diffuse_start(y, h, 0.01, q)
    m, x, cov = _compiled(y, h, 0.01, q)
    assert ref is not None and m == ref.samples
    np.testing.assert_allclose(cov, ref.cov, rtol=1e-12, atol=0)
    np.testing.assert_allclose(x, ref.x, rtol=1e-12, atol=1e-14)
    # d rows in general position determine the state: the start ends at the d-th sample it used
    used = np.isfinite(y[:m]) & np.all(np.isfinite(h[:m]), axis=1)
    assert np.count_nonzero(used) == d and used[m - 1]


def test_start_is_the_limit_of_a_wide_prior():
    """The reference's definition: the covariance filter from N(0, kappa I), kappa large, reaches the same
    x_m and P_m after the same samples (with drift and a missing one), to rounding of order 1 / kappa."""
    y, h = _series(d=2)
    y[1] = np.nan
    q = 0.05**2 * np.eye(2)
    ref = diffuse_start(y, h, 0.01, q)
    x, cov = np.zeros(2), 1e8 * np.eye(2)
    for k in range(ref.samples):
        x, cov = predict(x, cov, None, q)
        step = update(x, cov, y[k : k + 1], h[k : k + 1], np.array([[0.01]]), "joseph")
        x, cov = step.x, step.cov
    np.testing.assert_allclose(cov, ref.cov, rtol=1e-6)
    np.testing.assert_allclose(x, ref.x, rtol=1e-6, atol=1e-8)


def test_a_state_never_determined():
    """Rows that span one direction only (one sensor value): no start, in both."""
    y = np.arange(10.0)
    h = np.column_stack([np.full(10, 2.0), np.ones(10)])
    assert diffuse_start(y, h, 0.01, 0.01 * np.eye(2)) is None
    assert _compiled(y, h, 0.01, 0.01 * np.eye(2))[0] == 0
