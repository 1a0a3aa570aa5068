"""statsmodels' state-space models as the referee of kalcal.core.timevarying_filter.

statsmodels is the reference implementation of the linear Gaussian filter and its likelihood. Each test
builds the same model on both sides, on a dataset statsmodels ships, states each side's initialization,
and holds kalcal's filtered states and variances (after the diffuse period, where there is one), its
smoothed ones, and its log-likelihood at fixed parameters to statsmodels' to 1e-8 (relative to each
series' largest magnitude: the filters' rounding is ~1e-13 of it, so 1e-8 is a difference in the
algebra, not in rounding). With an exact diffuse start, statsmodels' ``llf`` is kalcal's conditional
log-likelihood plus the run's ``diffuse_term`` (module docstring of kalcal.core.timevarying_filter).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.optimize
import statsmodels.api as sm
from statsmodels.tsa.statespace.initialization import Initialization
from statsmodels.tsa.statespace.mlemodel import MLEModel

from kalcal.core.timevarying import TimeVaryingModel
from kalcal.core.timevarying_filter import filter_model, loglik, reference_filter, smooth

RTOL = 1e-8
LOG_2PI = np.log(2.0 * np.pi)


def _nile() -> np.ndarray:
    return sm.datasets.nile.load_pandas().data["volume"].to_numpy(float)


def _macro(column: str) -> np.ndarray:
    return sm.datasets.macrodata.load_pandas().data[column].to_numpy(float)


def _pair(y, *, h, v, phi, gamma, w, x0, m0, diffuse, b=None, u=None):
    """The same model for kalcal (a TimeVaryingModel) and statsmodels (an MLEModel's smoother results).

    h (J, p, d) and v (J, p, p) per row; statsmodels takes them as (p, d, J) and (p, p, J), its
    state_intercept c_t = B u_t (its c_t drives t -> t + 1, as kalcal's u_j drives row j -> j + 1).
    statsmodels' initialization: "known" (x0, m0) where no state is diffuse, "diffuse" (exact) where all
    are, and the two mixed (known for the proper states, exact diffuse for the others) otherwise.
    """
    y = np.asarray(y, dtype=float).reshape(len(y), -1)
    n, p = y.shape
    d = np.shape(phi)[0]
    b = np.zeros((d, 0)) if b is None else np.asarray(b, dtype=float)
    u = np.zeros((n, b.shape[1])) if u is None else np.asarray(u, dtype=float).reshape(n, -1)
    model = TimeVaryingModel(phi=phi, gamma=gamma, w=w, b=b, x0=x0, m0=m0, h=h, v=v, u=u, diffuse=diffuse,
                             sample_period=1.0, times=np.arange(n, dtype=float))  # fmt: skip
    mod = MLEModel(y, k_states=d, k_posdef=np.shape(gamma)[1])
    mod.ssm["design"] = np.transpose(h, (1, 2, 0))
    mod.ssm["obs_cov"] = np.transpose(v, (1, 2, 0))
    mod.ssm["transition"] = np.asarray(phi, dtype=float)
    mod.ssm["selection"] = np.asarray(gamma, dtype=float)
    mod.ssm["state_cov"] = np.asarray(w, dtype=float)
    if b.shape[1]:
        mod.ssm["state_intercept"] = (u @ b.T).T
    flags = np.asarray(diffuse, dtype=bool)
    if not flags.any():
        mod.ssm.initialize_known(np.asarray(x0, dtype=float), np.asarray(m0, dtype=float))
    elif flags.all():
        mod.ssm.initialize_diffuse()
    else:
        init = Initialization(d)
        for i in range(d):
            if flags[i]:
                init.set(i, "diffuse")
        known = np.flatnonzero(~flags)
        init.set((int(known[0]), int(known[-1]) + 1), "known", constant=np.asarray(x0)[known],
                 stationary_cov=np.asarray(m0)[np.ix_(known, known)])  # fmt: skip
        mod.ssm.initialize(init)
    return model, mod.ssm.smooth()


def _close(ours, theirs, what):
    """|ours - theirs| <= RTOL x the largest |theirs| of the series (each state's own scale)."""
    ours, theirs = np.asarray(ours), np.asarray(theirs)
    scale = np.max(np.abs(theirs), axis=0, keepdims=True)
    excess = np.abs(ours - theirs) - RTOL * np.maximum(scale, 1e-300)
    assert np.all(np.isfinite(ours)), what
    assert np.all(excess <= 0), f"{what}: worst excess {np.max(excess)} (scale {scale.ravel()})"


def _referee(model, res, y, *, diffuse_term=None):
    """Hold filter_model (and the numpy reference) to statsmodels' results; return the run."""
    run = filter_model(model, y)
    ref = reference_filter(model, y)
    start = run.proper_from
    assert start == max(res.nobs_diffuse - 1, 0)  # statsmodels counts the row that ends the period in it
    for ours in (run, ref):
        _close(ours.state[start:], res.filtered_state.T[start:], "filtered state")
        _close(ours.cov[start:], np.transpose(res.filtered_state_cov, (2, 0, 1))[start:], "filtered covariance")
        _close(ours.prior_state[start + 1 :], res.predicted_state.T[start + 1 : -1], "predicted state")
        _close(ours.loglik + ours.diffuse_term, res.llf, "log-likelihood")
    assert loglik(model, y) == pytest.approx(run.loglik, rel=1e-12)
    if diffuse_term is not None:
        assert run.diffuse_term == pytest.approx(diffuse_term, rel=1e-12, abs=1e-12)
    smoothed = smooth(run, model)
    _close(smoothed.state[start:], res.smoothed_state.T[start:], "smoothed state")
    _close(smoothed.cov[start:], np.transpose(res.smoothed_state_cov, (2, 0, 1))[start:], "smoothed covariance")
    assert np.all(np.isnan(smoothed.state[:start]))
    return run


def _local_level(y, s2_eps, s2_eta, *, diffuse=True, x0=0.0, p0=0.0):
    n = len(y)
    return _pair(y, h=np.ones((n, 1, 1)), v=np.full((n, 1, 1), s2_eps), phi=[[1.0]], gamma=[[1.0]], w=[[s2_eta]],
                 x0=[x0], m0=[[p0]], diffuse=[diffuse])  # fmt: skip


# Nile: the local level at Durbin & Koopman's maximum-likelihood variances (s2_eps = 15099, s2_eta =
# 1469.1, their ch. 2), diffuse level on both sides: F_inf = 1 at the first observation, so statsmodels'
# exact diffuse llf is the conditional one less 1/2 log 2 pi, and the first row is the one conditioned on.
def test_nile_local_level_diffuse():
    y = _nile()
    model, res = _local_level(y, 15099.0, 1469.1)
    run = _referee(model, res, y[:, None], diffuse_term=-0.5 * LOG_2PI)
    assert run.conditioned[:, 0].tolist() == [True] + [False] * (len(y) - 1)
    assert np.isnan(run.residual[0, 0]) and np.isfinite(run.residual[1:, 0]).all()
    # the conditional likelihood is the prediction-error decomposition of rows 1..J-1
    r, s = run.residual[1:, 0], run.innovation_cov[1:, 0, 0]
    assert run.loglik == pytest.approx(-0.5 * np.sum(LOG_2PI + np.log(s) + r * r / s), rel=1e-12)


# Nile with a known prior (statsmodels initialization="known", a = 1000, P = 1e5, an arbitrary proper
# prior) and missing years (NaN: 1881-1890 and two single years): no diffuse term, the llfs equal.
def test_nile_known_prior_with_missing_values():
    y = _nile().copy()
    y[10:20] = np.nan
    y[[40, 77]] = np.nan
    model, res = _local_level(y, 15099.0, 1469.1, diffuse=False, x0=1000.0, p0=1e5)
    run = _referee(model, res, y[:, None], diffuse_term=0.0)
    assert not run.measured[10:20].any() and not run.conditioned.any()
    assert np.isnan(run.nis[10:20]).all() and np.isfinite(run.nis[:10]).all()


# macrodata's log real GDP (x100) as a local linear trend: level and slope both exact diffuse. The
# variances are fixed, of the order of the series' quarterly noise (s2_eps = 0.1, level 0.3, slope 0.01).
# Each of the first two observations has F_inf = 1 (P_inf = I, then [[1, 1], [1, 1]] after the
# prediction), so statsmodels' llf is the conditional one less log 2 pi: 1/2 log 2 pi per diffuse state.
def test_macrodata_local_linear_trend_diffuse():
    y = 100.0 * np.log(_macro("realgdp"))
    n = len(y)
    h = np.tile([[[1.0, 0.0]]], (n, 1, 1))
    model, res = _pair(y, h=h, v=np.full((n, 1, 1), 0.1), phi=[[1.0, 1.0], [0.0, 1.0]], gamma=np.eye(2),
                       w=np.diag([0.3, 0.01]), x0=[0.0, 0.0], m0=np.zeros((2, 2)), diffuse=[True, True])  # fmt: skip
    run = _referee(model, res, y[:, None], diffuse_term=-LOG_2PI)
    assert run.conditioned[:2, 0].all() and not run.conditioned[2:].any()
    assert run.proper_from == 1
    assert np.isnan(run.state[0, 1]) and np.isfinite(run.state[0, 0])  # the level is determined, the slope not


# AR(1) plus noise on macrodata's inflation, demeaned, phi = 0.8 fixed on both sides; the prior is the
# stationary one, given to both as known (x0 = 0, M0 = s2_w / (1 - phi^2)). A known input drives it
# (b = 0.5 times the change in unemployment; statsmodels' state_intercept), to hold B u_j's row convention.
def test_macrodata_ar1_plus_noise_stationary_prior_and_input():
    y = _macro("infl")
    y = y - y.mean()
    n = len(y)
    u = np.append(np.diff(_macro("unemp")), 0.0)
    phi, s2_w = 0.8, 2.0
    model, res = _pair(y, h=np.ones((n, 1, 1)), v=np.full((n, 1, 1), 3.0), phi=[[phi]], gamma=[[1.0]], w=[[s2_w]],
                       x0=[0.0], m0=[[s2_w / (1 - phi**2)]], diffuse=[False], b=[[0.5]], u=u)  # fmt: skip
    _referee(model, res, y[:, None], diffuse_term=0.0)


# A regression with a time-varying row h_j = [unemp_j, 1] (inflation on unemployment, macrodata), its two
# coefficients random walks (W = diag(1e-3, 1e-2)), both exact diffuse, V = 4. The conditioned
# components are the first two rows, whose F_inf depend on the data: the constant is not 1/2 log 2 pi per
# diffuse state here, and the test proves which one it is.
def test_macrodata_time_varying_regression_diffuse():
    y, x = _macro("infl"), _macro("unemp")
    n = len(y)
    h = np.stack([x, np.ones(n)], axis=1)[:, None, :]
    model, res = _pair(y, h=h, v=np.full((n, 1, 1), 4.0), phi=np.eye(2), gamma=np.eye(2), w=np.diag([1e-3, 1e-2]),
                       x0=[0.0, 0.0], m0=np.zeros((2, 2)), diffuse=[True, True])  # fmt: skip
    run = _referee(model, res, y[:, None])
    assert run.conditioned[:2, 0].all() and not run.conditioned[2:].any()
    # F_inf,0 = x_0^2 + 1, and (P_inf = I - h_0^T h_0 / F_inf,0, Phi = I) F_inf,1 = (x_1 - x_0)^2 / (x_0^2 + 1):
    # the constant is -log 2 pi - log |x_1 - x_0|, not 1/2 log 2 pi per diffuse state
    assert run.diffuse_term == pytest.approx(-LOG_2PI - np.log(abs(x[1] - x[0])), rel=1e-12)
    assert abs(run.diffuse_term - (-LOG_2PI)) > 0.3


def _two_series():
    """100 log real GDP and 100 log real consumption, with gaps: component 1 missing on some rows,
    component 0 on others, both on two."""
    z = 100.0 * np.log(np.column_stack([_macro("realgdp"), _macro("realcons")]))
    z[5:9, 1] = np.nan
    z[30:33, 0] = np.nan
    z[[60, 61]] = np.nan
    return z


def _two_series_model(z, v, diffuse):
    """A local linear trend of GDP (level, slope) and consumption's offset from it (a constant state):
    h = [[1, 0, 0], [1, 0, 1]]."""
    n = len(z)
    h = np.tile([[1.0, 0.0, 0.0], [1.0, 0.0, 1.0]], (n, 1, 1))
    phi = np.array([[1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    gamma = np.array([[1.0, 0.0], [0.0, 1.0], [0.0, 0.0]])
    if diffuse:
        x0, m0, flags = np.zeros(3), np.zeros((3, 3)), [True, True, True]
    else:
        x0, m0, flags = np.array([z[0, 0], 0.8, z[0, 1] - z[0, 0]]), np.diag([4.0, 1.0, 9.0]), [False] * 3
    return _pair(z, h=h, v=np.broadcast_to(v, (n, 2, 2)).copy(), phi=phi, gamma=gamma, w=np.diag([0.3, 0.01]),
                 x0=x0, m0=m0, diffuse=flags)  # fmt: skip


# p = 2 with correlated measurement noise (correlation 0.5) and a known prior (statsmodels "known",
# the prior written in _two_series_model): the decorrelation by V's Cholesky factor restricted to the
# measured components, and each missing pattern, against statsmodels' joint filter.
def test_two_components_correlated_noise_with_one_missing():
    z = _two_series()
    model, res = _two_series_model(z, np.array([[0.2, 0.15], [0.15, 0.9]]), diffuse=False)
    run = _referee(model, res, z, diffuse_term=0.0)
    assert run.measured[5:9].tolist() == [[True, False]] * 4 and not run.measured[[60, 61]].any()
    assert np.isnan(run.innovation_cov[5, 1, 1]) and np.isfinite(run.innovation_cov[5, 0, 0])


# p = 2 with diagonal V and all three states exact diffuse on both sides: row 0's two components and
# row 1's first are conditioned on (F_inf > 0), each with F_inf = 1 in statsmodels' units, so the
# constant is 1/2 log 2 pi x 3 here.
def test_two_components_diffuse():
    z = _two_series()
    model, res = _two_series_model(z, np.diag([0.2, 0.9]), diffuse=True)
    run = _referee(model, res, z)
    assert run.conditioned.sum() == 3
    assert run.conditioned[0].all() and run.conditioned[1].tolist() == [True, False]
    assert run.diffuse_term == pytest.approx(-1.5 * LOG_2PI, rel=1e-12)


# Maximum likelihood of the Nile local level: kalcal's conditional likelihood maximised over the two
# log-variances by scipy (BFGS, gtol 1e-9), and statsmodels' fit of the same model with its exact diffuse
# likelihood (UnobservedComponents(use_exact_diffuse=True): its initialization="diffuse" is the
# approximate diffuse start with the first row burnt, whose maximiser is 15108 / 1464, 0.06% and 0.4%
# away), BFGS from Durbin & Koopman's values, gtol 1e-9, maxiter 1000. The two objectives differ by the
# constant diffuse_term alone (-1/2 log 2 pi here), so the maximisers agree: to 1e-5 relative, the
# optimizers' stopping error (the log-likelihood is flat there: statsmodels' BFGS, Nelder-Mead and
# L-BFGS-B at tight tolerances stop within 3e-6 of each other, their llfs within 1e-11).
def test_nile_maximum_likelihood_agrees_with_statsmodels():
    y = _nile()
    n = len(y)

    def objective(theta):
        s2_eps, s2_eta = np.exp(theta)
        model = TimeVaryingModel(phi=[[1.0]], gamma=[[1.0]], w=[[s2_eta]], b=np.zeros((1, 0)), x0=[0.0], m0=[[0.0]],
                                 h=np.ones((n, 1, 1)), v=np.full((n, 1, 1), s2_eps), u=np.zeros((n, 0)),
                                 diffuse=[True], sample_period=1.0, times=np.arange(n, dtype=float))  # fmt: skip
        return -loglik(model, y[:, None])

    ours = scipy.optimize.minimize(objective, np.log([10000.0, 1000.0]), method="BFGS", options={"gtol": 1e-9})
    mod = sm.tsa.UnobservedComponents(y, "llevel", use_exact_diffuse=True)
    theirs = mod.fit(start_params=[15000.0, 1500.0], method="bfgs", maxiter=1000, gtol=1e-9, disp=False)
    np.testing.assert_allclose(np.exp(ours.x), theirs.params, rtol=1e-5)
    np.testing.assert_allclose(np.exp(ours.x), [15099.0, 1469.1], rtol=1e-4)  # Durbin & Koopman's, to their digits
    assert -ours.fun - 0.5 * LOG_2PI == pytest.approx(theirs.llf, rel=1e-9)
