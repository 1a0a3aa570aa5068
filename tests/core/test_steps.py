"""The reference Kalman steps (predict, the Joseph and standard updates, a missing measurement, the NIS).

Oracles: FilterPy's ``KalmanFilter`` on the same measurements (its ``update(None)`` for a missing one),
the textbook formulas written out with an inverse, Python loops over single realizations, and the
degenerate filter with H = 0 that only propagates.
"""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from kalcal.core.missing import measured
from kalcal.core.sqrt_form import cholesky_factor, gram, sqrt_update
from kalcal.core.steps import covariance_pass, gain_and_covariance, nis, predict, summed_nis, update
from kalcal.errors import ConfigError
from kalcal.filters.gains import run_with_gains
from kalcal.scenarios.accel_gps.settings import AccelGpsScenario
from kalcal.scenarios import build_scenario
from kalcal.scenarios.accel_gps.sampled import sample_accel_gps_errors
from tests._helpers import assert_close, cov_atol
from tests.core._models import blind_model


@pytest.fixture(scope="module")
def scenario() -> AccelGpsScenario:
    # The report's scenario: 150 fixes, 6000 accelerometer samples.
    return build_scenario("accel-gps")


def test_unknown_update_form_is_config_error():
    with pytest.raises(ConfigError, match="form"):
        gain_and_covariance(np.eye(2), np.eye(2), np.eye(2), form="sqrt")  # type: ignore[arg-type]



# --------------------------------------------------------------------------------------------------
# the filter against FilterPy


def test_filter_matches_filterpy_on_accel_gps_data(scenario):
    model = scenario.filter_model()
    _, measurements = sample_accel_gps_errors(scenario, np.random.default_rng(2024), 2)
    z_all = measurements[1]  # one realization, (K, 2)
    n_updates, m = z_all.shape[0], model.steps_per_update
    q = model.gamma @ model.w @ model.gamma.T

    kf = KalmanFilter(dim_x=3, dim_z=2)
    kf.F, kf.Q, kf.H, kf.R = model.phi.copy(), q.copy(), model.h.copy(), model.v.copy()
    kf.x = model.x0.reshape(3, 1).copy()
    kf.P = model.m0.copy()

    x, cov = model.x0, model.m0
    ours_x, ours_p, ref_x, ref_p = [], [], [], []
    for k in range(n_updates):
        for _ in range(m):
            kf.predict()
            x, cov = predict(x, cov, model.phi, q)
        kf.update(z_all[k])
        result = update(x, cov, z_all[k], model.h, model.v)
        x, cov = result.x, result.cov
        ours_x.append(x)
        ours_p.append(cov)
        ref_x.append(kf.x[:, 0].copy())
        ref_p.append(kf.P.copy())
    ours_x, ours_p, ref_x, ref_p = map(np.array, (ours_x, ours_p, ref_x, ref_p))
    assert_close(ours_p, ref_p, atol=cov_atol(ref_p, 1e-10), what="P vs FilterPy")
    # States: compare in units of the filter's own standard deviation (the bias is ~1e-3 m/s^2).
    sigma = np.sqrt(np.diagonal(ref_p, axis1=1, axis2=2))
    assert_close(ours_x, ref_x, rtol=1e-10, atol=1e-10 * sigma, what="x vs FilterPy")

    # The interval-rate pass gives the same covariances and the same estimates.
    schedule = covariance_pass(model, n_updates)
    assert_close(schedule.posterior_cov, ref_p, atol=cov_atol(ref_p, 1e-10), what="pass P vs FilterPy")
    run = run_with_gains(schedule, model.h, z_all[None], model.x0)
    assert_close(run.posterior[0], ref_x, rtol=1e-10, atol=1e-10 * sigma, what="run_with_gains vs FilterPy")


# --------------------------------------------------------------------------------------------------
# batches equal loops over single realizations


def test_predict_batch_equals_loop():
    rng = np.random.default_rng(7)
    n, d = 5, 3
    x = rng.standard_normal((n, d))
    a = rng.standard_normal((n, d, d))
    cov = a @ np.swapaxes(a, 1, 2)
    phi = rng.standard_normal((d, d))
    q = np.eye(d) * 0.3
    xb, mb = predict(x, cov, phi, q)
    for i in range(n):
        xi, mi = predict(x[i], cov[i], phi, q)
        np.testing.assert_allclose(xb[i], xi, rtol=1e-14, atol=1e-14)
        np.testing.assert_allclose(mb[i], mi, rtol=1e-14, atol=1e-14)
        np.testing.assert_allclose(mi, phi @ cov[i] @ phi.T + q, rtol=1e-13)
    # Per-realization transitions (n, d, d) too.
    phis = rng.standard_normal((n, d, d))
    xb, mb = predict(x, cov, phis, q)
    for i in range(n):
        xi, mi = predict(x[i], cov[i], phis[i], q)
        np.testing.assert_allclose(xb[i], xi, rtol=1e-14, atol=1e-14)
        np.testing.assert_allclose(mb[i], mi, rtol=1e-14, atol=1e-14)


@pytest.mark.parametrize("per_realization_h", [False, True])
@pytest.mark.parametrize("form", ["joseph", "standard"])
def test_update_batch_equals_loop(per_realization_h, form):
    rng = np.random.default_rng(8)
    n, d, p = 6, 3, 2
    x = rng.standard_normal((n, d))
    a = rng.standard_normal((n, d, d))
    cov = a @ np.swapaxes(a, 1, 2) + np.eye(d)
    z = rng.standard_normal((n, p))
    h = rng.standard_normal((n, p, d)) if per_realization_h else rng.standard_normal((p, d))
    v = np.diag([0.5, 2.0])
    batch = update(x, cov, z, h, v, form)
    assert batch.gain.shape == (n, d, p)
    for i in range(n):
        hi = h[i] if per_realization_h else h
        single = update(x[i], cov[i], z[i], hi, v, form)
        for got, want in zip(batch, single):
            np.testing.assert_allclose(got[i], want, rtol=1e-12, atol=1e-12)
        # And the textbook formulas, written out.
        s = hi @ cov[i] @ hi.T + v
        gain = cov[i] @ hi.T @ np.linalg.inv(s)
        np.testing.assert_allclose(single.gain, gain, rtol=1e-10)
        np.testing.assert_allclose(single.x, x[i] + gain @ (z[i] - hi @ x[i]), rtol=1e-10)
        np.testing.assert_allclose(single.cov, (np.eye(d) - gain @ hi) @ cov[i], rtol=1e-9, atol=1e-12)


# --------------------------------------------------------------------------------------------------
# degenerate oracle: H = 0 only propagates


def test_update_with_zero_h_changes_nothing():
    model = blind_model()
    x = np.array([1.5, -0.25])
    result = update(x, model.m0, np.array([123.0]), model.h, model.v)
    np.testing.assert_array_equal(result.gain, np.zeros((2, 1)))
    np.testing.assert_array_equal(result.x, x)
    np.testing.assert_allclose(result.cov, model.m0, rtol=1e-15)
    np.testing.assert_array_equal(result.residual, [123.0])
    np.testing.assert_allclose(result.innovation_cov, model.v, rtol=1e-15)



# --------------------------------------------------------------------------------------------------
# Phi = None is the identity


def test_predict_without_transition_is_the_identity_transition():
    rng = np.random.default_rng(12)
    x = rng.standard_normal((4, 3))
    a = rng.standard_normal((4, 3, 3))
    cov = 0.5 * (a @ np.swapaxes(a, 1, 2) + np.swapaxes(a @ np.swapaxes(a, 1, 2), 1, 2))
    q = np.diag([1e-3, 2e-3, 3e-3])
    xbar, m = predict(x, cov, None, q)
    xi, mi = predict(x, cov, np.eye(3), q)
    np.testing.assert_array_equal(xbar, xi)
    np.testing.assert_array_equal(m, mi)


# --------------------------------------------------------------------------------------------------
# a missing measurement is a prediction only


def _prior(rng, n=6, d=3, p=2):
    x = rng.standard_normal((n, d))
    a = rng.standard_normal((n, d, d))
    cov = a @ np.swapaxes(a, 1, 2) + np.eye(d)
    return x, cov, rng.standard_normal((n, p)), rng.standard_normal((p, d)), np.diag([0.5, 2.0])


def test_measured_flags_non_finite_measurements_and_rows():
    z = np.array([[1.0, 2.0], [np.nan, 2.0], [1.0, np.inf], [1.0, 2.0]])
    h = np.ones((4, 2, 3))
    h[3, 1, 2] = np.nan
    np.testing.assert_array_equal(measured(z, h), [True, False, False, False])
    np.testing.assert_array_equal(measured(z[:1], np.ones((2, 3))), [True])


@pytest.mark.parametrize("form", ["joseph", "standard", "sqrt"])
def test_missing_measurement_keeps_the_prior_like_filterpy(form):
    rng = np.random.default_rng(13)
    x, cov, z, h, v = _prior(rng)
    z[[1, 4], 0] = np.nan
    if form == "sqrt":
        result = sqrt_update(x, cholesky_factor(cov), z, h, cholesky_factor(v))
        posterior, innovation = gram(result.chol), result.innovation_chol
    else:
        result = update(x, cov, z, h, v, form)
        posterior, innovation = result.cov, result.innovation_cov
    for i in range(x.shape[0]):
        kf = KalmanFilter(dim_x=3, dim_z=2)
        kf.x, kf.P, kf.H, kf.R = x[i].reshape(3, 1).copy(), cov[i].copy(), h.copy(), v.copy()
        kf.update(None if i in (1, 4) else z[i])
        assert_close(result.x[i], kf.x[:, 0], rtol=1e-12, atol=1e-12, what=f"x {i}")
        assert_close(posterior[i], kf.P, atol=cov_atol(kf.P, 1e-12), what=f"P {i}")
    for i in (1, 4):
        np.testing.assert_array_equal(result.x[i], x[i])
        np.testing.assert_array_equal(result.gain[i], 0.0)
        assert np.all(np.isnan(result.residual[i])) and np.all(np.isnan(innovation[i]))
        if form != "sqrt":
            np.testing.assert_array_equal(posterior[i], cov[i])
    # The realizations that were measured are updated exactly as in a batch without the missing ones.
    rest = [0, 2, 3, 5]
    if form == "sqrt":
        dense = sqrt_update(x[rest], cholesky_factor(cov[rest]), z[rest], h, cholesky_factor(v))
        np.testing.assert_array_equal(result.chol[rest], dense.chol)
    else:
        dense = update(x[rest], cov[rest], z[rest], h, v, form)
        np.testing.assert_array_equal(posterior[rest], dense.cov)
    np.testing.assert_array_equal(result.x[rest], dense.x)
    np.testing.assert_array_equal(result.residual[rest], dense.residual)


def test_missing_measurement_equals_the_blind_update():
    """A missing measurement and H = 0 (a measurement that sees nothing) leave x and P alike."""
    model = blind_model()
    x = np.array([1.5, -0.25])
    blind = update(x, model.m0, np.array([123.0]), model.h, model.v)
    missing = update(x, model.m0, np.array([np.nan]), np.array([[1.0, 0.0]]), model.v)
    np.testing.assert_array_equal(missing.x, blind.x)
    np.testing.assert_allclose(missing.cov, blind.cov, rtol=1e-15)
    np.testing.assert_array_equal(missing.gain, blind.gain)


@pytest.mark.parametrize("m", [1, 2, 3])
def test_nis_is_the_quadratic_form_of_the_inverse_at_every_size(m):
    """r^T S^{-1} r against the textbook inverse, one realization at a time, over batch axes that broadcast
    (an S per update, shared by the realizations); each size takes its own path (a division, the 2 x 2
    closed form, Cholesky)."""
    rng = np.random.default_rng(40 + m)
    a = rng.standard_normal((6, m, m + 2))
    s = a @ np.swapaxes(a, 1, 2) + 0.1 * np.eye(m)  # (K, m, m)
    r = rng.standard_normal((5, 6, m)) * 3.0  # (n, K, m)
    got = nis(r, s)
    assert got.shape == (5, 6)
    want = np.array([[r[i, k] @ np.linalg.inv(s[k]) @ r[i, k] for k in range(6)] for i in range(5)])
    np.testing.assert_allclose(got, want, rtol=1e-12)
    # the normalized innovation's squared norm: L^-1 r by the Cholesky factor, S = L L^T
    white = np.linalg.solve(np.linalg.cholesky(s), r[..., None])[..., 0]
    np.testing.assert_allclose(nis(white), got, rtol=1e-12)
    # summed over the realizations that share S, from their outer products
    np.testing.assert_allclose(summed_nis(np.einsum("nka,nkb->kab", r, r), s), got.sum(axis=0), rtol=1e-12)


def test_nis_of_a_missing_measurement_is_nan_and_a_wrong_shape_is_refused():
    s = np.array([[2.0, 0.3], [0.3, 1.0]])
    assert np.isnan(nis(np.array([np.nan, 1.0]), s))
    assert np.isnan(nis(np.array([1.0, 1.0]), np.full((2, 2), np.nan)))
    with pytest.raises(ValueError, match="innovation_cov"):
        nis(np.zeros(2), np.eye(3))
