"""The compiled diffuse likelihood of the scale-bias fit, step by step against the numpy reference.

The reference is the diffuse start (:func:`kalcal.core.diffuse.diffuse_start`), then the reference
regression filter (:func:`kalcal.filters.regression.run_regression_filter`, Joseph form) from sample m,
then :func:`kalcal.core.likelihood.innovation_loglik`. The two compute the same equations in a different
order (closed loops against batched products and LAPACK's solves), so they agree to rounding: measured
1e-15 relative in log L, 7e-15 absolute in the normalized innovations and 8e-12 relative in the smallest
entry of P (an off-diagonal one near 0); held to 1e-12 relative (P: 1e-12 of its largest entry).
"""

from __future__ import annotations

import numpy as np
import pytest

from kalcal.core.diffuse import diffuse_start
from kalcal.core.likelihood import innovation_loglik
from kalcal.filters.regression import run_regression_filter
from kalcal.scenarios.scale_bias.filter import regressors
from kalcal.scenarios.scale_bias.likelihood import diffuse_filter_steps, diffuse_loglik


def _log(n=300, seed=11, missing=()):
    rng = np.random.default_rng(seed)
    z = 2.0 * np.sin(np.linspace(0, 12, n)) + rng.normal(0, 0.05, n)
    theta1 = 1.01 + np.cumsum(rng.normal(0, 1e-3, n))
    v = theta1 * z + 0.2 + rng.normal(0, 0.1, n)
    v[list(missing)] = np.nan
    return v, z


@pytest.mark.parametrize("drift", [0.0, 1e-3])
@pytest.mark.parametrize("missing", [(), (1, 57, 58, 200)])
def test_compiled_likelihood_equals_the_reference_step_by_step(drift, missing):
    v, z = _log(missing=missing)
    noise = 0.1
    steps = diffuse_filter_steps(v, z, noise, drift)
    start = diffuse_start(v, regressors(z), noise**2, drift**2 * np.eye(2))
    m = start.samples
    rest = run_regression_filter(v[m:], regressors(z[m:]), start.x, start.cov, noise**2, drift**2 * np.eye(2), "joseph")
    # P from the start's last sample on
    np.testing.assert_allclose(steps["cov"][m - 1], start.cov, rtol=1e-12)
    np.testing.assert_allclose(steps["cov"][m:], rest.cov, rtol=1e-12, atol=1e-12 * np.abs(rest.cov).max())
    assert np.all(np.isnan(steps["cov"][: m - 1]))
    # innovations and S where a sample was used; NaN at the same samples (a missing one, the start's)
    np.testing.assert_array_equal(np.isnan(steps["residual"][m:]), np.isnan(rest.residual))
    assert np.all(np.isnan(steps["residual"][:m]))
    used = ~np.isnan(rest.residual)
    np.testing.assert_allclose(steps["innovation_var"][m:][used], rest.innovation_var[used], rtol=1e-12)
    white = rest.residual[used] / np.sqrt(rest.innovation_var[used])
    np.testing.assert_allclose(steps["normalized"][m:][used], white, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(steps["residual"][m:][used], rest.residual[used], rtol=1e-12, atol=1e-12)
    # the log-likelihood, and the samples in it
    reference = innovation_loglik(rest.residual[:, None], rest.innovation_var[:, None, None])
    assert steps["samples"] == np.count_nonzero(used)
    assert steps["loglik"] == pytest.approx(reference, rel=1e-12)
    # the hot path (no recording) is the same computation
    assert diffuse_loglik(v, z, noise, drift)[0] == steps["loglik"]
