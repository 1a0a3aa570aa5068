"""statsmodels as the referee of ``kalcal fit MODEL.toml``: the maximum-likelihood estimates and intervals.

Each model is written as a model file with a ``[data]`` table and its dataset (one statsmodels ships) as a
CSV in tmp_path, fitted by :func:`kalcal.fit`, and the same model is fitted by statsmodels.

**Initialization.** Every state starts exact diffuse on both sides: kalcal's ``diffuse = [...]`` (its
likelihood is the conditional one) and statsmodels' exact diffuse initialization
(``UnobservedComponents(use_exact_diffuse=True)``; an ``MLEModel`` with ``initialization="diffuse"``,
which is exact). statsmodels' ``llf`` is kalcal's log L plus the fit's ``diffuse_term``; in these models
the components conditioned on have F_inf independent of W and V (and, for the AR(1), of phi: only row 0
is conditioned, F_inf = 1), so the two objectives differ by a constant and have the same maximizer.

**statsmodels' optimum** is found to a tight tolerance (BFGS, gtol 1e-10, maxiter 2000; its defaults
stop up to 1% short on the Nile). The estimates agree to :data:`RTOL_ESTIMATE` = 1e-5 relative: kalcal's
L-BFGS-B stops on its own tolerance (measured: within 1.8e-6 of statsmodels' on these four models).

**Intervals.** kalcal's observed-information intervals are Wald intervals in u = ln(variance) (u = phi
for phi): u_hat +- z se, se from the inverse of the negated Hessian of log L in u. statsmodels' own
``conf_int()`` is Wald on the variances themselves (a different, symmetric interval), so the referee is
the Wald interval in u computed from statsmodels' Hessian: its complex-step Hessian of ``llf`` in the
variances (``MLEModel.hessian(approx_complex_step=True)``, which statsmodels divides by the number of
observations: multiplied back), taken to u by J H J with J = diag(theta) (exact at the maximum, where the
gradient is zero), over the same parameters as kalcal's (a variance kalcal reports at its bound is held).
kalcal's se (central differences of its own log L) agree to :data:`RTOL_SE` = 1e-4 relative (measured:
at most 2.2e-5 over these models), and so do the intervals' ends.

A variance whose maximum-likelihood value is 0 (the local linear trend's irregular on log GDP: statsmodels
reaches 7e-18) is reported "consistent with 0" at the search's lower bound, its upper limit the value
where statsmodels' own llf along it (the others at the estimate) has fallen by chi2.ppf(0.95, 1) / 2.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pandas as pd
import pytest
import statsmodels.api as sm
from statsmodels.tsa.statespace.mlemodel import MLEModel

import kalcal
from kalcal.fitting.mle import drop_of
from kalcal.stats.distributions import normal_isf

RTOL_ESTIMATE = 1e-5
RTOL_SE = 1e-4
Z95 = float(normal_isf(0.025))


def _macro(column: str) -> np.ndarray:
    return sm.datasets.macrodata.load_pandas().data[column].to_numpy(float)


def _files(tmp_path, text: str, columns: dict[str, np.ndarray]):
    model = tmp_path / "model.toml"
    model.write_text(text)
    data = tmp_path / "data.csv"
    pd.DataFrame(columns).to_csv(data, index=False)
    return model, data


class _Model(MLEModel):
    """A linear Gaussian model whose noise variances (and phi[0, 0]) are its parameters, exact diffuse.

    ``names``: "phi" first where phi is free, then v, then the diagonal of W (Gamma = I). The optimizer
    runs on sqrt(variance) (and phi / sqrt(1 - phi^2)), statsmodels' usual transforms.
    """

    def __init__(self, y, *, design, phi, names):
        k = np.shape(phi)[0]
        super().__init__(y, k_states=k, k_posdef=k, initialization="diffuse")
        self.ssm["design"] = design
        self.ssm["transition"] = np.array(phi, dtype=float)
        self.ssm["selection"] = np.eye(k)
        self._names = list(names)
        self._phi = names[0] == "phi"

    @property
    def param_names(self):
        return self._names

    @property
    def start_params(self):
        return np.full(len(self._names), 0.5)

    def transform_params(self, unconstrained):
        out = unconstrained**2
        if self._phi:
            out[0] = unconstrained[0] / np.sqrt(1.0 + unconstrained[0] ** 2)
        return out

    def untransform_params(self, constrained):
        out = np.sqrt(np.abs(constrained))
        if self._phi:
            out[0] = constrained[0] / np.sqrt(1.0 - constrained[0] ** 2)
        return out

    def update(self, params, **kwargs):
        params = super().update(params, **kwargs)
        i = 1 if self._phi else 0
        if self._phi:
            self.ssm["transition", 0, 0] = params[0]
        self.ssm["obs_cov", 0, 0] = params[i]
        self.ssm["state_cov"] = np.diag(params[i + 1 :])


def _tight(mod, start):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return mod.fit(start_params=start, method="bfgs", maxiter=2000, gtol=1e-10, disp=False)


def _statsmodels_se(mod, params, log_scale, keep):
    """se of u (ln of a variance, or phi) from statsmodels' complex-step Hessian of llf, over ``keep``."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        hess = mod.hessian(params, approx_complex_step=True) * (mod.nobs - mod.ssm.loglikelihood_burn)
    jac = np.diag(np.where(log_scale, params, 1.0))
    hess_u = (jac @ hess @ jac)[np.ix_(keep, keep)]
    return np.sqrt(np.diag(np.linalg.inv(-hess_u)))


def _referee(ours, keys, theirs, mod, log_scale):
    """kalcal's estimates and observed-information intervals against statsmodels' (module docstring)."""
    params = np.asarray(theirs.params, dtype=float)
    assert ours.converged
    wald = [i for i, key in enumerate(keys) if ours.parameters[key].se is not None]
    for i, key in enumerate(keys):
        p = ours.parameters[key]
        if p.at_bound:
            continue
        assert p.value == pytest.approx(params[i], rel=RTOL_ESTIMATE), key
    # statsmodels' llf = kalcal's conditional log L + diffuse_term; with a variance held at the search's lower
    # bound (start / 1e6) rather than at 0, kalcal's maximum is short of statsmodels' by log L's fall from 0 to
    # that bound (measured: 4e-6 on the local linear trend's irregular)
    exact = ours.loglik + ours.extra["diffuse_term"]
    if any(ours.parameters[key].at_bound and params[i] < 1e-12 for i, key in enumerate(keys)):
        assert 0.0 <= theirs.llf - exact < 1e-4
    else:
        assert exact == pytest.approx(theirs.llf, rel=1e-9)
    se = _statsmodels_se(mod, params, np.asarray(log_scale), wald)
    for a, i in enumerate(wald):
        p = ours.parameters[keys[i]]
        assert p.se == pytest.approx(se[a], rel=RTOL_SE), keys[i]
        u = np.log(params[i]) if log_scale[i] else params[i]
        low, high = (np.exp([u - Z95 * se[a], u + Z95 * se[a]]) if log_scale[i] else (u - Z95 * se[a], u + Z95 * se[a]))
        assert p.ci_low == pytest.approx(low, rel=RTOL_SE) and p.ci_high == pytest.approx(high, rel=RTOL_SE), keys[i]
    return wald


# The Nile as a local level (Durbin & Koopman ch. 2): level and irregular variances both free.
def test_nile_local_level_fit_equals_statsmodels(tmp_path):
    y = sm.datasets.nile.load_pandas().data["volume"].to_numpy(float)
    model, data = _files(tmp_path, """
name = "nile"
phi = [[1.0]]
gamma = [[1.0]]
h = [[1.0]]
w = [[1000.0]]
v = [[10000.0]]
x0 = [0.0]
m0 = [[0.0]]
diffuse = ["level"]
state_names = ["level"]
[data]
measurements = ["volume"]
""", {"volume": y})  # fmt: skip
    ours = kalcal.fit(model, data=data, free="filter.v,filter.w")
    mod = sm.tsa.UnobservedComponents(y, "llevel", use_exact_diffuse=True)
    theirs = _tight(mod, [15000.0, 1500.0])
    wald = _referee(ours, ["filter.v", "filter.w"], theirs, mod, [True, True])
    assert wald == [0, 1]
    assert ours.extra["diffuse_term"] == pytest.approx(-0.5 * np.log(2 * np.pi), rel=1e-12)
    np.testing.assert_allclose([ours.value("filter.v"), ours.value("filter.w")], [15099.0, 1469.1], rtol=1e-4)


# 100 log real GDP as a local linear trend (level and slope random walks), three variances free. The
# irregular's maximum likelihood is 0 (statsmodels: 7e-18): kalcal reports it consistent with 0 at the
# search's lower bound (the file's 0.1 / 1e6), its upper limit where statsmodels' llf along it has fallen
# by 1.92; the two others get Wald intervals from the observed information with the irregular held.
def test_local_linear_trend_fit_with_a_variance_at_zero(tmp_path):
    y = 100.0 * np.log(_macro("realgdp"))
    model, data = _files(tmp_path, """
phi = [[1.0, 1.0], [0.0, 1.0]]
gamma = [[1.0, 0.0], [0.0, 1.0]]
h = [[1.0, 0.0]]
w = [[0.3, 0.0], [0.0, 0.01]]
v = [[0.1]]
x0 = [0.0, 0.0]
m0 = [[0.0, 0.0], [0.0, 0.0]]
diffuse = ["level", "slope"]
state_names = ["level", "slope"]
[data]
measurements = ["gdp"]
""", {"gdp": y})  # fmt: skip
    keys = ["filter.v", "filter.w.1", "filter.w.2"]
    ours = kalcal.fit(model, data=data, free=",".join(keys))
    mod = sm.tsa.UnobservedComponents(y, "lltrend", use_exact_diffuse=True)
    theirs = _tight(mod, [0.1, 0.3, 0.01])
    assert theirs.params[0] < 1e-12  # statsmodels' irregular variance: 0 to its rounding
    wald = _referee(ours, keys, theirs, mod, [True, True, True])
    assert wald == [1, 2]
    irregular = ours.parameters["filter.v"]
    assert irregular.at_bound and irregular.ci_low == 0.0 and irregular.value == pytest.approx(0.1 / 1e6)
    assert "consistent with 0" in irregular.note
    # the upper limit: statsmodels' llf with the irregular there and the others at the estimate
    at_limit = mod.loglike(np.array([irregular.ci_high, *theirs.params[1:]]))
    assert theirs.llf - at_limit == pytest.approx(drop_of(0.95), abs=2e-3)  # brentq's xtol 1e-4 in ln(v)


# AR(1) plus noise on macrodata's inflation, demeaned: phi (linear scale, within [-1, 1]), the AR's
# variance and the noise's, all free. The state starts exact diffuse on both sides (statsmodels' stationary
# prior would depend on phi, which a model file's m0 cannot).
def test_ar1_plus_noise_phi_free(tmp_path):
    y = _macro("infl")
    y = y - y.mean()
    model, data = _files(tmp_path, """
phi = [[0.5]]
gamma = [[1.0]]
h = [[1.0]]
w = [[2.0]]
v = [[3.0]]
x0 = [0.0]
m0 = [[0.0]]
diffuse = ["x1"]
[data]
measurements = ["infl"]
""", {"infl": y})  # fmt: skip
    keys = ["filter.phi", "filter.v", "filter.w"]
    ours = kalcal.fit(model, data=data, free=",".join(keys))
    mod = _Model(y, design=np.ones((1, 1)), phi=[[0.5]], names=["phi", "v", "w"])
    theirs = _tight(mod, [0.5, 3.0, 2.0])
    assert _referee(ours, keys, theirs, mod, [False, True, True]) == [0, 1, 2]
    assert ours.parameters["filter.phi"].scale == "linear"
    assert 0.9 < ours.value("filter.phi") < 0.95  # inflation is persistent (statsmodels: 0.932)
    assert any("diffuse_term may depend on phi" in note for note in ours.notes)


# The same with phi fixed at 0.8 on both sides: the two variances free.
def test_ar1_plus_noise_phi_fixed(tmp_path):
    y = _macro("infl")
    y = y - y.mean()
    model, data = _files(tmp_path, """
phi = [[0.8]]
gamma = [[1.0]]
h = [[1.0]]
w = [[2.0]]
v = [[3.0]]
x0 = [0.0]
m0 = [[0.0]]
diffuse = ["x1"]
[data]
measurements = ["infl"]
""", {"infl": y})  # fmt: skip
    keys = ["filter.v", "filter.w"]
    ours = kalcal.fit(model, data=data, free=",".join(keys))
    mod = _Model(y, design=np.ones((1, 1)), phi=[[0.8]], names=["v", "w"])
    theirs = _tight(mod, [3.0, 2.0])
    assert _referee(ours, keys, theirs, mod, [True, True]) == [0, 1]


# A regression with a time-varying row h_j = [unemp_j, 1] (inflation on unemployment), both
# coefficients random walks, exact diffuse; the noise and both walks' variances free. The slope's walk
# variance (statsmodels: 1.9e-3) is not bounded away from 0 by the log: kalcal's estimate equals
# statsmodels', and its likelihood-ratio interval reaches the search's lower bound ("consistent with 0").
def test_time_varying_regression_fit(tmp_path):
    y, x = _macro("infl"), _macro("unemp")
    model, data = _files(tmp_path, """
phi = [[1.0, 0.0], [0.0, 1.0]]
gamma = [[1.0, 0.0], [0.0, 1.0]]
h = [["unemp", 1.0]]
w = [[0.001, 0.0], [0.0, 0.01]]
v = [[4.0]]
x0 = [0.0, 0.0]
m0 = [[0.0, 0.0], [0.0, 0.0]]
diffuse = ["slope", "intercept"]
state_names = ["slope", "intercept"]
[data]
measurements = ["infl"]
""", {"infl": y, "unemp": x})  # fmt: skip
    keys = ["filter.v", "filter.w.1", "filter.w.2"]
    ours = kalcal.fit(model, data=data, free=",".join(keys))
    design = np.stack([x, np.ones(len(x))])[None]
    mod = _Model(y, design=design, phi=np.eye(2), names=["v", "w1", "w2"])
    theirs = _tight(mod, [4.0, 1e-3, 1e-2])
    assert _referee(ours, keys, theirs, mod, [True, True, True]) == [0, 2]
    slope = ours.parameters["filter.w.1"]
    assert slope.at_bound and slope.value == pytest.approx(theirs.params[1], rel=RTOL_ESTIMATE)


# model.toml: the file with the fitted values, read back as a model file; its likelihood on the log is
# the fit's maximum (what calibrate runs), and fit.json holds each key's value and interval.
def test_model_toml_holds_the_fit(tmp_path):
    from kalcal.core.timevarying_filter import loglik
    from kalcal.scenarios.model_file.data import bind
    from kalcal.scenarios.model_file.model import load_model_file

    y = _macro("infl")
    y = y - y.mean()
    model, data = _files(tmp_path, """
phi = [[0.5]]
gamma = [[1.0]]
h = [[1.0]]
w = [[2.0]]
v = [[3.0]]
x0 = [0.0]
m0 = [[0.0]]
diffuse = ["x1"]
[data]
measurements = ["infl"]
""", {"infl": y})  # fmt: skip
    ours = kalcal.fit(model, data=data, free="filter.phi,filter.w,filter.v", out=tmp_path / "fit")
    written = {p.name for p in (tmp_path / "fit").iterdir()}
    assert {"fit.json", "fit.png", "model.toml"} <= written and "filter.toml" not in written
    fitted = load_model_file(tmp_path / "fit" / "model.toml")
    assert fitted.filter.phi[0, 0] == ours.value("filter.phi")
    assert fitted.filter.w[0, 0] == ours.value("filter.w") and fitted.filter.v[0, 0] == ours.value("filter.v")
    assert loglik(bind(fitted, data).filter, bind(fitted, data).z) == pytest.approx(ours.loglik, rel=1e-12)
    document = json.loads((tmp_path / "fit" / "fit.json").read_text())
    for key in ("filter.phi", "filter.w", "filter.v"):
        entry = document["parameters"][key]
        assert entry["value"] == ours.value(key) and entry["ci_low"] < entry["value"] < entry["ci_high"]
