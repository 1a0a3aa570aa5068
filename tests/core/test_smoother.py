"""The RTS smoother against the dense joint Gaussian, loops over single realizations and degenerate cases.

Oracle: stack the states at the K updates and the measurements into one Gaussian vector; the mean and
covariance of the states given every measurement come from one solve with the measurements'
covariance. The smoother's recursion must reproduce them.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import block_diag

from kalcal.core.model import LinearGaussianModel
from kalcal.core.smoother import rts_smooth
from kalcal.core.steps import covariance_pass, interval_transition, predict, update
from kalcal.errors import ConfigError
from kalcal.filters.gains import run_with_gains
from tests._helpers import assert_close, cov_atol


def _spd(rng, d, shift=0.5):
    a = rng.standard_normal((d, d))
    return a @ a.T + shift * np.eye(d)


def _time_varying(rng, n_updates=7, d=3, p=2):
    """Per-update Phi_k, Q_k, H_k, V_k and a prior N(x0, M0)."""
    phis = rng.standard_normal((n_updates, d, d)) * 0.6 + np.eye(d)
    qs = np.stack([_spd(rng, d, 0.1) * 0.3 for _ in range(n_updates)])
    hs = rng.standard_normal((n_updates, p, d))
    vs = np.stack([_spd(rng, p) for _ in range(n_updates)])
    return phis, qs, hs, vs, rng.standard_normal(d), _spd(rng, d, 1.0)


def _filter(phis, qs, hs, vs, x0, m0, z):
    """Batched predict/update over z (n, K, p): priors, posteriors."""
    n, n_updates, _ = z.shape
    d = x0.shape[0]
    out = {name: np.empty((n, n_updates, d)) for name in ("xbar", "xhat")}
    out |= {name: np.empty((n_updates, d, d)) for name in ("m", "p")}
    x, cov = np.broadcast_to(x0, (n, d)), m0
    for k in range(n_updates):
        x, cov = predict(x, cov, phis[k], qs[k])
        out["xbar"][:, k], out["m"][k] = x, cov  # the covariances do not depend on the data: (d, d)
        result = update(x, cov, z[:, k], hs[k], vs[k])
        x, cov = result.x, result.cov
        out["xhat"][:, k], out["p"][k] = x, cov
    return out


def _dense_smoother(phis, qs, hs, vs, x0, m0, z):
    """E[x_1..x_K | z_1..z_K] and Cov by one solve: x_k = Phi_k x_{k-1} + w_k, z_k = H_k x_k + v_k."""
    n_updates, d, _ = phis.shape
    # [x_0, x_1, ..., x_K] = A [x_0, w_1, ..., w_K]
    a = np.zeros(((n_updates + 1) * d, (n_updates + 1) * d))
    for k in range(n_updates + 1):
        a[k * d:(k + 1) * d, k * d:(k + 1) * d] = np.eye(d)
        for j in range(k - 1, -1, -1):
            a[k * d:(k + 1) * d, j * d:(j + 1) * d] = a[k * d:(k + 1) * d, (j + 1) * d:(j + 2) * d] @ phis[j]
    mean = a @ np.concatenate([x0, np.zeros(n_updates * d)])
    cov = a @ block_diag(m0, *qs) @ a.T
    mean, cov = mean[d:], cov[d:, d:]
    h = block_diag(*hs)
    s = h @ cov @ h.T + block_diag(*vs)
    cross = cov @ h.T
    innovations = z.reshape(z.shape[0], -1) - h @ mean
    smoothed_mean = mean + np.linalg.solve(s, innovations.T).T @ cross.T
    smoothed_cov = cov - cross @ np.linalg.solve(s, cross.T)
    blocks = np.stack([smoothed_cov[k * d:(k + 1) * d, k * d:(k + 1) * d] for k in range(n_updates)])
    return smoothed_mean.reshape(z.shape[0], n_updates, d), blocks


def test_smoother_equals_the_dense_joint_gaussian_time_varying():
    rng = np.random.default_rng(1)
    phis, qs, hs, vs, x0, m0 = _time_varying(rng)
    z = rng.standard_normal((4, phis.shape[0], hs.shape[1])) * 2.0
    run = _filter(phis, qs, hs, vs, x0, m0, z)
    smoothed = rts_smooth(run["xhat"], run["p"], run["xbar"], run["m"], phis)
    mean, cov = _dense_smoother(phis, qs, hs, vs, x0, m0, z)
    assert smoothed.state.shape == (4, 7, 3) and smoothed.cov.shape == (7, 3, 3) and smoothed.gain.shape == (6, 3, 3)
    sigma = np.sqrt(np.diagonal(cov, axis1=1, axis2=2))
    assert_close(smoothed.state, mean, rtol=1e-9, atol=1e-9 * sigma, what="smoothed mean")
    assert_close(smoothed.cov, cov, atol=cov_atol(cov, 1e-9), what="smoothed covariance")


def test_smoother_over_a_fixed_gain_run_equals_the_dense_joint_gaussian():
    """A time-invariant model at its update rate: shared covariances (K, d, d), states (n, K, d)."""
    rng = np.random.default_rng(2)
    model = LinearGaussianModel(
        phi=[[1.0, 0.1], [0.0, 1.0]],
        gamma=[[0.005], [0.1]],
        h=[[1.0, 0.0]],
        w=[[0.3]],
        v=[[0.5]],
        x0=[1.0, -0.5],
        m0=[[4.0, 0.5], [0.5, 1.0]],
        steps_per_update=3,
        sample_period=0.1,
    )
    n_updates = 12
    schedule = covariance_pass(model, n_updates)
    z = rng.standard_normal((5, n_updates, 1))
    run = run_with_gains(schedule, model.h, z, model.x0)
    phis = np.broadcast_to(schedule.phi_interval, (n_updates, 2, 2))
    smoothed = rts_smooth(run.posterior, schedule.posterior_cov, run.prior, schedule.prior_cov, phis)
    phi_m, q_m = interval_transition(model.phi, model.gamma, model.w, model.steps_per_update)
    mean, cov = _dense_smoother(
        np.broadcast_to(phi_m, (n_updates, 2, 2)),
        np.broadcast_to(q_m, (n_updates, 2, 2)),
        np.broadcast_to(model.h, (n_updates, 1, 2)),
        np.broadcast_to(model.v, (n_updates, 1, 1)),
        model.x0,
        model.m0,
        z,
    )
    sigma = np.sqrt(np.diagonal(cov, axis1=1, axis2=2))
    assert_close(smoothed.state, mean, rtol=1e-9, atol=1e-9 * sigma, what="smoothed mean")
    assert_close(smoothed.cov, cov, atol=cov_atol(cov, 1e-9), what="smoothed covariance")


def test_batch_equals_loop_and_the_last_update_is_the_filters():
    rng = np.random.default_rng(3)
    phis, qs, hs, vs, x0, m0 = _time_varying(rng, n_updates=6)
    z = rng.standard_normal((3, 6, 2))
    run = _filter(phis, qs, hs, vs, x0, m0, z)
    # per-realization covariances and transitions too: (n, K, d, d)
    p_batch = np.broadcast_to(run["p"], (3, 6, 3, 3))
    batch = rts_smooth(run["xhat"], p_batch, run["xbar"], run["m"], np.broadcast_to(phis, (3, 6, 3, 3)))
    for i in range(3):
        single = rts_smooth(run["xhat"][i], run["p"], run["xbar"][i], run["m"], phis)
        np.testing.assert_allclose(batch.state[i], single.state, rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(batch.cov[i], single.cov, rtol=1e-13, atol=1e-13)
    np.testing.assert_array_equal(batch.state[:, -1], run["xhat"][:, -1])
    np.testing.assert_array_equal(batch.cov[:, -1], p_batch[:, -1])
    # Smoothing uses more data: P_k - P_s,k is positive semi-definite.
    shrink = np.linalg.eigvalsh(run["p"] - batch.cov[0])
    assert np.all(shrink > -1e-12 * np.abs(run["p"]).max())


def test_with_zero_h_the_smoother_changes_nothing():
    """No information in the measurements: every smoothed estimate is the filter's (the propagated prior)."""
    rng = np.random.default_rng(4)
    phis, qs, _, vs, x0, m0 = _time_varying(rng, n_updates=5)
    hs = np.zeros((5, 2, 3))
    run = _filter(phis, qs, hs, vs, x0, m0, rng.standard_normal((2, 5, 2)))
    smoothed = rts_smooth(run["xhat"], run["p"], run["xbar"], run["m"], phis)
    np.testing.assert_allclose(smoothed.state, run["xhat"], rtol=1e-12, atol=1e-12)
    assert_close(smoothed.cov, run["p"], atol=cov_atol(run["p"], 1e-12), what="P_s")


def test_shapes_that_disagree_are_config_errors():
    x, cov = np.zeros((4, 2)), np.broadcast_to(np.eye(2), (4, 2, 2))
    with pytest.raises(ConfigError, match="transition"):
        rts_smooth(x, cov, x, cov, np.eye(2))  # one Phi for all updates must be broadcast explicitly
    with pytest.raises(ConfigError, match="prior_cov"):
        rts_smooth(x, cov, x, cov[:3], cov)
