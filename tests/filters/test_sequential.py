"""The compiled sequential filter against the reference steps, fix by fix.

Oracle: :func:`kalcal.core.steps.predict` and :func:`~kalcal.core.steps.update` (Joseph form) in a
Python loop over the same per-fix transitions and noise, with and without missing fixes; the gate's NIS
against :func:`kalcal.core.steps.nis`.
"""

from __future__ import annotations

import numpy as np
import pytest

from kalcal.core.steps import nis, predict, update
from kalcal.filters.sequential import sequential_filter
from tests._helpers import assert_close, cov_atol


def _fixes(n: int, seed: int = 21):
    rng = np.random.default_rng(seed)
    dt = rng.uniform(0.1, 0.3, n)
    phis = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
    phis[:, 0, 1], phis[:, 0, 2], phis[:, 1, 2] = dt, -0.5 * dt**2, -dt
    a = rng.standard_normal((n, 3, 3)) * 1e-2
    qs = a @ np.swapaxes(a, 1, 2)
    vs = np.array([np.diag(rng.uniform(0.5, 2.0, 2)) for _ in range(n)])
    return phis, qs, np.eye(3)[:2], vs, rng.standard_normal((n, 2)), np.zeros(3), np.diag([100.0, 1.0, 0.01])


def _reference(phis, qs, h, vs, z, x0, m0):
    x, cov, rows = x0, m0, []
    for k in range(z.shape[0]):
        x, cov = predict(x, cov, phis[k], qs[k])
        prior_x, prior_cov = x, cov
        result = update(x, cov, z[k], h, vs[k], "joseph")
        x, cov = result.x, result.cov
        rows.append((x, cov, result.residual, result.innovation_cov, prior_x, prior_cov))
    return [np.array(column) for column in zip(*rows)]


@pytest.mark.parametrize("missing", [(), (0, 7, 8, 29)], ids=["every fix", "missing fixes"])
def test_compiled_kernel_equals_the_reference_steps_fix_by_fix(missing):
    phis, qs, h, vs, z, x0, m0 = _fixes(30)
    z[list(missing), 1] = np.nan
    compiled = sequential_filter(phis, qs, h, vs, z, x0, m0)
    reference = _reference(phis, qs, h, vs, z, x0, m0)
    for name, got, want in zip(compiled._fields, compiled, reference):
        if name.endswith("cov"):
            assert_close(got, want, atol=cov_atol(want, 1e-12), what=name)
        else:
            np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-14, err_msg=name)
    for k in missing:
        np.testing.assert_array_equal(compiled.state[k], compiled.prior_state[k])
        np.testing.assert_array_equal(compiled.cov[k], compiled.prior_cov[k])
        assert np.all(np.isnan(compiled.residual[k])) and np.all(np.isnan(compiled.innovation_cov[k]))


def test_the_gate_rejects_exactly_the_fixes_whose_nis_exceeds_the_threshold():
    """Against the reference steps with the gate's rule applied by hand: a fix whose NIS under its prior
    exceeds the threshold leaves the prior as the posterior; with no threshold the numbers are identical."""
    phis, qs, h, vs, z, x0, m0 = _fixes(40)
    z = z.copy()
    z[[5, 17, 30]] += 40.0
    threshold = 13.8  # chi2.ppf(0.999, 2)
    rejected = np.zeros(40, dtype=bool)
    run = sequential_filter(phis, qs, h, vs, z, x0, m0, threshold=threshold, rejected=rejected)
    x, cov, want = x0, m0, []
    for k in range(40):
        x, cov = predict(x, cov, phis[k], qs[k])
        result = update(x, cov, z[k], h, vs[k], "joseph")
        want.append(nis(result.residual, result.innovation_cov) > threshold)
        if not want[-1]:
            x, cov = result.x, result.cov
        np.testing.assert_allclose(run.state[k], x, rtol=1e-10, atol=1e-12)
        assert_close(run.cov[k], cov, atol=cov_atol(cov, 1e-10))
    np.testing.assert_array_equal(rejected, want)
    assert list(np.flatnonzero(rejected)) == [5, 17, 30]
    # a threshold above every NIS of the ungated filter: the gate's branch runs at every fix, rejects
    # none, and the numbers are the ungated filter's to the bit
    x, cov, largest = x0, m0, 0.0
    for k in range(40):
        x, cov = predict(x, cov, phis[k], qs[k])
        result = update(x, cov, z[k], h, vs[k], "joseph")
        largest = max(largest, float(nis(result.residual, result.innovation_cov)))
        x, cov = result.x, result.cov
    assert largest > threshold  # the outliers: the gate below would reject them, were it not above them
    none_rejected = np.ones(40, dtype=bool)
    plain = sequential_filter(phis, qs, h, vs, z, x0, m0)
    above = sequential_filter(phis, qs, h, vs, z, x0, m0, threshold=2.0 * largest, rejected=none_rejected)
    assert not none_rejected.any()
    for a, b in zip(plain, above):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("p", [1, 2, 3])
def test_the_gates_nis_is_the_reference_nis_fix_by_fix(p):
    """The compiled gate's NIS equals :func:`kalcal.core.steps.nis` at every fix, to 1e-9: from the
    reference posterior before fix k, a threshold 1e-9 below the reference NIS of fix k rejects it and one
    1e-9 above keeps it (one, two and three rows: the kernel's division and its Cholesky solve)."""
    phis, qs, _, vs3, z3, x0, m0 = _fixes(12, seed=30 + p)
    rng = np.random.default_rng(p)
    h = np.eye(3)[:p] + 0.2 * rng.standard_normal((p, 3))
    a = rng.standard_normal((12, p, p))
    vs = a @ np.swapaxes(a, 1, 2) + 0.5 * np.eye(p)
    z = rng.standard_normal((12, p)) * 2.0
    x, cov = x0, m0
    for k in range(12):
        xbar, prior = predict(x, cov, phis[k], qs[k])
        result = update(xbar, prior, z[k], h, vs[k], "joseph")
        want = float(nis(result.residual, result.innovation_cov))
        for factor, rejects in ((1.0 - 1e-9, True), (1.0 + 1e-9, False)):
            rejected = np.zeros(1, dtype=bool)
            sequential_filter(phis[k:k + 1], qs[k:k + 1], h, vs[k:k + 1], z[k:k + 1], x, cov, threshold=want * factor, rejected=rejected)
            assert rejected[0] == rejects, (k, want, factor)
        x, cov = result.x, result.cov
