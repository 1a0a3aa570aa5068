"""The time-varying-regressor filter (the calibration note's filter) against independent oracles.

Oracles: weighted least squares with the prior as pseudo-measurements (numpy.linalg.lstsq on the
whitened stacked system), the note's equations against the Joseph and standard forms, a Python loop
over single series against the batch, and the degenerate filter with h = 0 that only propagates.
"""

from __future__ import annotations

import numpy as np
import pytest

from kalcal.core.steps import update
from kalcal.errors import ConfigError
from kalcal.filters.regression import note_update, run_regression_filter, scalar_update
from kalcal.scenarios.scale_bias.filter import filter_scale_bias, regressors
from kalcal.scenarios import build_scenario
from kalcal.scenarios.scale_bias.simulation import sample_scale_bias
from tests._helpers import assert_close, cov_atol


def _problem(seed: int = 0, n: int = 3, k: int = 120):
    """n series of k measurements with regressors [z_k, 1] like the scenario's, and a full prior."""
    rng = np.random.default_rng(seed)
    z = 2.0 * np.sin(0.3 * np.arange(1, k + 1))[None, :] + 0.3 * rng.standard_normal((n, k))
    h = regressors(z)
    x0 = np.array([1.01, 0.05])
    cov0 = np.array([[4e-4, 3e-5], [3e-5, 1e-2]])
    theta = x0 + rng.standard_normal((n, 2)) @ np.linalg.cholesky(cov0).T
    r = 0.04
    y = np.einsum("nkd,nd->nk", h, theta) + np.sqrt(r) * rng.standard_normal((n, k))
    return y, h, x0, cov0, r


def _least_squares(y, h, x0, cov0, r):
    """The posterior after each k as the WLS solution of [prior; measurements 1..k], by lstsq.

    Rows: L0^{-1} theta = L0^{-1} x0 (the prior as two pseudo-measurements, L0 L0^T = P0) and
    h_j theta / sqrt(R) = y_j / sqrt(R). The covariance is (A^T A)^{-1}, from the normal equations.
    """
    chol = np.linalg.cholesky(cov0)
    prior_rows = np.linalg.solve(chol, np.eye(2))
    estimates, covariances = [], []
    for k in range(1, y.size + 1):
        a = np.vstack([prior_rows, h[:k] / np.sqrt(r)])
        b = np.concatenate([prior_rows @ x0, y[:k] / np.sqrt(r)])
        solution, *_ = np.linalg.lstsq(a, b, rcond=None)
        estimates.append(solution)
        covariances.append(np.linalg.solve(a.T @ a, np.eye(2)))
    return np.array(estimates), np.array(covariances)


@pytest.mark.parametrize("form", ["joseph", "standard", "note"])
def test_constant_parameters_equal_weighted_least_squares(form):
    y, h, x0, cov0, r = _problem()
    run = run_regression_filter(y, h, x0, cov0, r, np.zeros((2, 2)), form)
    for i in range(y.shape[0]):
        theta, cov = _least_squares(y[i], h[i], x0, cov0, r)
        scale = np.sqrt(np.diagonal(cov, axis1=1, axis2=2))
        assert_close(run.posterior[i], theta, atol=1e-9 * scale, what=f"theta, series {i}")
        assert_close(run.cov[i], cov, atol=cov_atol(cov, 1e-9), what=f"P, series {i}")


def test_scenario_filter_equals_least_squares_on_a_simulated_log():
    scenario = build_scenario("scale-bias")
    samples = sample_scale_bias(scenario, np.random.default_rng(5), 1)
    run = filter_scale_bias(scenario, samples.reference[0], samples.sensor[0])
    prior = scenario.filter_prior()
    theta, cov = _least_squares(
        samples.reference[0], regressors(samples.sensor[0]), prior.mean, prior.cov, scenario.filter_noise_variance()
    )
    scale = np.sqrt(np.diagonal(cov, axis1=1, axis2=2))
    assert_close(run.posterior, theta, atol=1e-9 * scale, what="theta")
    assert_close(run.cov, cov, atol=cov_atol(cov, 1e-9), what="P")


def _note_by_hand(x, cov, y, h, r):
    """The note's eqs. (14)-(18) for one scalar measurement, written out here (not by the package):
    r = y - h x, S = h P h^T + R, K = P h^T / S, P^+ = P - K (h P), x^+ = x + K r, for one series."""
    ph = cov @ h
    s = h @ ph + r
    k = ph / s
    residual = y - h @ x
    return x + k * residual, cov - np.outer(k, ph), residual, s, k


@pytest.mark.parametrize("drift", [0.0, 3e-3])
def test_note_form_is_the_notes_equations_and_agrees_with_joseph_and_standard(drift):
    y, h, x0, cov0, r = _problem(seed=1, n=4, k=200)
    q = drift**2 * np.eye(2)
    runs = {form: run_regression_filter(y, h, x0, cov0, r, q, form) for form in ("joseph", "standard", "note")}
    joseph = runs["joseph"]
    scale = np.sqrt(np.diagonal(joseph.cov, axis1=-2, axis2=-1))
    # the standard form against the Joseph form: two updates, equal in exact arithmetic
    assert_close(runs["standard"].posterior, joseph.posterior, atol=1e-10 * scale, what="standard theta")
    assert_close(runs["standard"].cov, joseph.cov, atol=cov_atol(joseph.cov, 1e-10), what="standard P")
    np.testing.assert_allclose(runs["standard"].innovation_var, joseph.innovation_var, rtol=1e-12)
    np.testing.assert_allclose(runs["standard"].residual, joseph.residual, rtol=0, atol=1e-10 * np.sqrt(r))
    # the note form against its equations written out by hand, series by series
    note = runs["note"]
    for i in range(y.shape[0]):
        x, cov = x0, cov0
        for k in range(y.shape[1]):
            cov = cov + q  # (12): P^- = P^+ + Q
            x, cov, residual, s, _ = _note_by_hand(x, cov, y[i, k], h[i, k], r)
            np.testing.assert_allclose(note.posterior[i, k], x, rtol=1e-12, atol=1e-12 * scale[i, k].max())
            assert_close(note.cov[i, k], cov, atol=cov_atol(cov, 1e-10), what=f"note P, series {i}, step {k}")
            assert note.residual[i, k] == pytest.approx(residual, rel=1e-12, abs=1e-12 * np.sqrt(r))
            assert note.innovation_var[i, k] == pytest.approx(s, rel=1e-12)


def test_note_update_is_the_notes_equations_and_the_kalman_update():
    rng = np.random.default_rng(7)
    a = rng.standard_normal((5, 2, 2))
    cov = a @ np.swapaxes(a, 1, 2) + np.eye(2)
    x, h, y = rng.standard_normal((5, 2)), rng.standard_normal((5, 2)), rng.standard_normal(5)
    note = note_update(x, cov, y, h, 0.3)
    for i in range(5):
        want_x, want_cov, residual, s, gain = _note_by_hand(x[i], cov[i], y[i], h[i], 0.3)
        np.testing.assert_allclose(note.x[i], want_x, rtol=1e-13)
        np.testing.assert_allclose(note.cov[i], want_cov, rtol=1e-12, atol=1e-15)
        assert note.residual[i] == pytest.approx(residual, rel=1e-13)
        assert note.innovation_var[i] == pytest.approx(s, rel=1e-14)
        np.testing.assert_allclose(note.gain[i], gain, rtol=1e-13)
    ref = update(x, cov, y[:, None], h[:, None, :], np.array([[0.3]]), "standard")
    joseph = scalar_update(x, cov, y, h, 0.3, "joseph")
    np.testing.assert_allclose(joseph.cov, ref.cov, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("form", ["joseph", "note"])
def test_batch_equals_a_loop_over_single_series(form):
    y, h, x0, cov0, r = _problem(seed=2, n=5, k=80)
    q = 1e-6 * np.eye(2)
    batch = run_regression_filter(y, h, x0, cov0, r, q, form)
    for i in range(y.shape[0]):
        single = run_regression_filter(y[i], h[i], x0, cov0, r, q, form)
        for name in ("prior", "posterior", "cov", "residual", "innovation_var"):
            np.testing.assert_allclose(getattr(batch, name)[i], getattr(single, name), rtol=1e-14, atol=1e-15, err_msg=name)


def test_zero_regressor_only_propagates():
    y, h, x0, cov0, r = _problem(n=1, k=10)
    q = np.diag([1e-4, 4e-4])
    run = run_regression_filter(y[0], np.zeros_like(h[0]), x0, cov0, r, q)
    np.testing.assert_array_equal(run.posterior, np.broadcast_to(x0, (10, 2)))
    np.testing.assert_allclose(run.cov, cov0 + np.arange(1, 11)[:, None, None] * q, rtol=1e-14)
    np.testing.assert_allclose(run.innovation_var, r, rtol=1e-15)


def test_missing_measurements_are_skipped():
    y, h, x0, cov0, r = _problem(seed=3, n=1, k=60)
    y, h = y[0], h[0]
    gappy, holey_h = y.copy(), h.copy()
    gappy[[4, 17, 18]] = np.nan
    holey_h[30, 0] = np.nan
    keep = np.ones(60, dtype=bool)
    keep[[4, 17, 18, 30]] = False
    run = run_regression_filter(gappy, holey_h, x0, cov0, r, np.zeros((2, 2)))
    dense = run_regression_filter(y[keep], h[keep], x0, cov0, r, np.zeros((2, 2)))
    np.testing.assert_array_equal(run.used, keep)
    np.testing.assert_allclose(run.posterior[keep], dense.posterior, rtol=1e-13)
    np.testing.assert_allclose(run.cov[keep], dense.cov, rtol=1e-12)
    assert np.all(np.isnan(run.residual[~keep])) and np.all(np.isnan(run.innovation_var[~keep]))
    # A skipped sample carries the estimate forward.
    np.testing.assert_array_equal(run.posterior[4], run.posterior[3])


def test_bad_form_and_shapes_are_refused():
    y, h, x0, cov0, r = _problem(n=1, k=5)
    with pytest.raises(ConfigError, match="form"):
        run_regression_filter(y, h, x0, cov0, r, np.zeros((2, 2)), "square-root")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="h: expected shape"):
        run_regression_filter(y, h[:, :4], x0, cov0, r, np.zeros((2, 2)))


@pytest.mark.parametrize("form", ["joseph", "standard", "note"])
def test_scalar_update_matches_filterpy(form):
    """A scalar measurement is the reference update with p = 1 (its gain a division): FilterPy agrees."""
    from filterpy.kalman import KalmanFilter

    rng = np.random.default_rng(9)
    a = rng.standard_normal((4, 2, 2))
    cov = a @ np.swapaxes(a, 1, 2) + np.eye(2)
    x, h, y = rng.standard_normal((4, 2)), rng.standard_normal((4, 2)), rng.standard_normal(4)
    step = scalar_update(x, cov, y, h, 0.3, form)
    for i in range(4):
        kf = KalmanFilter(dim_x=2, dim_z=1)
        kf.x, kf.P, kf.H, kf.R = x[i].reshape(2, 1).copy(), cov[i].copy(), h[i][None, :].copy(), np.array([[0.3]])
        kf.update(np.array([[y[i]]]))
        np.testing.assert_allclose(step.x[i], kf.x[:, 0], rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(step.cov[i], kf.P, rtol=1e-11, atol=1e-14)
        np.testing.assert_allclose(step.innovation_var[i], kf.S[0, 0], rtol=1e-14)
        np.testing.assert_allclose(step.gain[i], kf.K[:, 0], rtol=1e-12, atol=1e-14)
