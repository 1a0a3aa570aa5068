"""The Kalman filter, RTS smoother and log-likelihood of a :class:`~kalcal.core.timevarying.TimeVaryingModel`.

One row j = 0..J-1 of the model is a prediction from row j - 1 (none at row 0, whose prior is the
model's) and an update with the components of z_j that are measured (:func:`~kalcal.core.timevarying.measured_components`)::

    predict:  xbar_j = Phi xhat_{j-1} + B u_{j-1},     M_j = Phi P_{j-1} Phi^T + Gamma W Gamma^T
    update:   the measured components o of row j, decorrelated by V_{j,oo} = L L^T (Cholesky):
              z* = L^{-1} z_{j,o},  H* = L^{-1} H_{j,o},  then one scalar update per component i
              (e = z*_i - h*_i x, F = h*_i P h*_i^T + 1, K = P h*_i^T / F, x += K e, P Joseph form)

The univariate treatment (Koopman & Durbin 2000, which statsmodels' state-space models use) gives the
posterior of the joint update, handles a component missing from a row by leaving it out of o, and makes
the exact diffuse initialization a scalar recursion. Per row the run reports the joint residual
r_j = z_j - H_j xbar_j, S_j = H_j M_j H_j^T + V_j, and NIS_j = r_{j,o}^T S_{j,oo}^{-1} r_{j,o} over the
measured components (NaN where none is measured, and in S's rows and columns of unmeasured components).

**Diffuse states** (exact diffuse initialization, Koopman 1997; Durbin & Koopman 2012, 5.2-5.3 and 6.4).
The prior covariance of row 0 is P = P_* + kappa P_inf, kappa -> infinity, with P_* = M0 and P_inf the
diagonal 0/1 matrix of the ``diffuse`` flags. Both parts are predicted (P_inf = Phi P_inf Phi^T) and,
per component, with M_inf = P_inf h^T, M_* = P_* h^T, F_inf = h P_inf h^T, F_* = h P_* h^T + 1:

- F_inf > 0 (the component sees a diffuse direction): K0 = M_inf / F_inf, x += K0 e,
  P_inf -= M_inf M_inf^T / F_inf,  P_* = (I - K0 h) P_* (I - K0 h)^T + K0 K0^T (the kappa^0 term of the
  limit). The component is *conditioned on*: it carries no information about the parameters of the noise.
- F_inf = 0: the ordinary update of P_* (P_inf is unchanged), and an ordinary term of the likelihood.

The diffuse period ends with the row whose posterior has P_inf = 0 (statsmodels' rule: its squared
Frobenius norm at most ``DIFFUSE_TOL``; F_inf counts as 0 at most ``DIFFUSE_TOL`` |h*|^2 max(1, max diag P_inf)).
A state whose P_inf diagonal is nonzero has no finite mean or variance: the run's state, prior_state, cov
and prior_cov are NaN in its entries (rows and columns) there; residual, innovation_cov and nis are NaN
on rows whose prior is not proper.

**The likelihood** is the conditional one: log p(components not conditioned on | conditioned ones), the
prediction-error decomposition over every measured component with F_inf = 0,
``-1/2 sum (log 2 pi + log F + e^2 / F) - sum log L_ii``, the last the Jacobian of the decorrelation. It
differs from statsmodels' exact diffuse log-likelihood (``initialization="diffuse"``, its ``llf``),
which adds ``-1/2 log(2 pi F_inf)`` for each conditioned component, by the run's ``diffuse_term``:

    statsmodels' llf = loglik + diffuse_term,    diffuse_term = -1/2 sum_conditioned log(2 pi F_inf)

That is 1/2 log 2 pi per diffuse state only where each F_inf = 1 (a local level, a local linear trend);
for a regression row h_0 = [x_0, 1] it is -1/2 (2 log 2 pi + log F_inf terms that depend on the data);
it never depends on W or V, so the two give the same maximum-likelihood estimates of the noise, but it
depends on Phi (tests/core/test_statsmodels_referee.py holds each statement).

:func:`reference_filter` is the numpy reference; :func:`filter_model` and :func:`loglik` run the diffuse
period the same way, then the proper rows compiled (:mod:`kalcal.core.timevarying_kernels`, held to the
reference at every row); :func:`smooth` is :func:`kalcal.core.smoother.rts_smooth` over the rows after
the diffuse period (the rows before it are NaN: the exact diffuse smoother is not implemented).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from kalcal.core.smoother import SmoothedRun, rts_smooth
from kalcal.core.steps import gain_and_covariance, nis, predict_covariance
from kalcal.core.timevarying import TimeVaryingModel, measured_components
from kalcal.core.timevarying_kernels import run_rows
from kalcal.linalg import symmetrize

__all__ = [
    "DIFFUSE_TOL", "DiffuseStep", "TimeVaryingRun", "Whitened", "diffuse_step", "filter_model", "loglik",
    "predict_diffuse", "reference_filter", "smooth", "whiten",
]

#: the diffuse period ends once |P_inf|_F^2 <= DIFFUSE_TOL (P_inf starts as a 0/1 matrix); F_inf counts as
#: 0 below DIFFUSE_TOL |h*|^2 max(1, max diag P_inf) (rounding after a rank reduction is ~1e-16 of that scale)
DIFFUSE_TOL = 1e-10
_LOG_2PI = float(np.log(2.0 * np.pi))
_ONE = np.ones((1, 1))


class TimeVaryingRun(NamedTuple):
    """The filter's run over J rows, d states, p components (NaN conventions in the module docstring)."""

    state: np.ndarray  #: posterior xhat_j, (J, d)
    cov: np.ndarray  #: posterior P_j, (J, d, d)
    prior_state: np.ndarray  #: xbar_j, (J, d) (row 0: the model's prior)
    prior_cov: np.ndarray  #: M_j, (J, d, d)
    residual: np.ndarray  #: r_j = z_j - H_j xbar_j, (J, p), NaN where not measured
    innovation_cov: np.ndarray  #: S_j = H_j M_j H_j^T + V_j, (J, p, p)
    nis: np.ndarray  #: r_{j,o}^T S_{j,oo}^{-1} r_{j,o} over the measured components o, (J,), dimensionless
    measured: np.ndarray  #: (J, p) bool
    conditioned: np.ndarray  #: (J, p) bool, the components the diffuse likelihood conditions on
    loglik: float  #: the conditional log-likelihood (natural log)
    diffuse_term: float  #: -1/2 sum log(2 pi F_inf) over the conditioned components: statsmodels' llf - loglik
    proper_from: int  #: the first row whose posterior is proper (0 without diffuse states; J if never)


class Whitened(NamedTuple):
    """The measured components of each row, decorrelated (the first ``count[j]`` slots of row j)."""

    hs: np.ndarray  #: h*_{j,i} = (L_j^{-1} H_{j,o})_i, (J, p, d), in 1 / the states' units
    zs: np.ndarray  #: z*_{j,i} = (L_j^{-1} z_{j,o})_i, (J, p), dimensionless
    log_l: np.ndarray  #: log L_{j,ii}, (J, p)
    count: np.ndarray  #: the number of measured components, (J,) int64
    origin: np.ndarray  #: the component of z_j each slot comes from, (J, p) int64 (-1: unused)


def whiten(model: TimeVaryingModel, z: np.ndarray, measured: np.ndarray) -> Whitened:
    """Decorrelate each row's measured components by the Cholesky factor of V restricted to them.

    Rows are grouped by their pattern of measured components (at most 2^p groups), each group's factors
    and triangular solves batched; a diagonal V is a division by its square root, and two correlated
    components a closed-form factor.

    Parameters
    ----------
    model : TimeVaryingModel
    z : ndarray, shape (J, p)
    measured : ndarray of bool, shape (J, p)

    Returns
    -------
    Whitened
    """
    n, p, d = model.h.shape
    hs, zs = np.zeros((n, p, d)), np.zeros((n, p))
    log_l = np.zeros((n, p))
    origin = np.full((n, p), -1, dtype=np.int64)
    count = measured.sum(axis=1).astype(np.int64)
    codes = measured.astype(np.int64) @ (1 << np.arange(p, dtype=np.int64))
    for code in np.unique(codes):
        rows = np.flatnonzero(codes == code)
        comps = np.flatnonzero((code >> np.arange(p)) & 1)
        k = comps.size
        if k == 0:
            continue
        v = model.v[np.ix_(rows, comps, comps)]
        h, zo = model.h[np.ix_(rows, comps)], z[np.ix_(rows, comps)]
        if k == 1 or not np.any(v[:, ~np.eye(k, dtype=bool)]):  # diagonal: L = sqrt(V)
            scale = np.sqrt(np.diagonal(v, axis1=1, axis2=2))
            hs[rows, :k] = h / scale[:, :, None]
            zs[rows, :k] = zo / scale
            log_l[rows, :k] = np.log(scale)
        elif k == 2:  # L = [[l11, 0], [l21, l22]] in closed form: a batched LAPACK call costs 5x these lines
            l11 = np.sqrt(v[:, 0, 0])
            l21 = 0.5 * (v[:, 1, 0] + v[:, 0, 1]) / l11
            l22 = np.sqrt(v[:, 1, 1] - l21 * l21)
            first_h, first_z = h[:, 0] / l11[:, None], zo[:, 0] / l11
            hs[rows, 0], zs[rows, 0] = first_h, first_z
            hs[rows, 1] = (h[:, 1] - l21[:, None] * first_h) / l22[:, None]
            zs[rows, 1] = (zo[:, 1] - l21 * first_z) / l22
            log_l[rows, 0], log_l[rows, 1] = np.log(l11), np.log(l22)
        else:
            lower = np.linalg.cholesky(v)
            solved = np.linalg.solve(lower, np.concatenate([h, zo[:, :, None]], axis=2))
            hs[rows, :k], zs[rows, :k] = solved[:, :, :d], solved[:, :, d]
            log_l[rows, :k] = np.log(np.diagonal(lower, axis1=1, axis2=2))
        origin[rows, :k] = comps
    return Whitened(hs, zs, log_l, count, origin)


class _State:
    """The numpy reference's running state: the mean, P_*, P_inf (None once the diffuse period is over)."""

    def __init__(self, model: TimeVaryingModel):
        self.x = model.x0.copy()
        self.x[model.diffuse] = 0.0
        self.cov = model.m0.copy()
        self.inf = np.diag(model.diffuse.astype(float)) if model.diffuse.any() else None
        self.loglik = 0.0
        self.diffuse_term = 0.0


def _predict(state: _State, model: TimeVaryingModel, gq: np.ndarray, bu_prev: np.ndarray) -> None:
    state.x = model.phi @ state.x + bu_prev
    state.cov = predict_covariance(state.cov, model.phi, gq)
    if state.inf is not None:
        state.inf = predict_diffuse(state.inf, model.phi)


class DiffuseStep(NamedTuple):
    """One decorrelated component's exact diffuse update (F_inf > 0)."""

    gain: np.ndarray  #: K0 = P_inf h^T / F_inf, (d,)
    cov: np.ndarray  #: P_* after it, (d, d)
    inf: np.ndarray | None  #: P_inf after it, (d, d); None once it counts as 0 (the diffuse period is over)
    f_inf: float  #: F_inf = h P_inf h^T


def diffuse_step(cov: np.ndarray, inf: np.ndarray, h: np.ndarray) -> DiffuseStep | None:
    """The exact diffuse update of P_* and P_inf by one decorrelated component h (d,) of unit noise, or None
    where F_inf counts as 0 (then the ordinary update of P_* applies). The one step that the log filter
    (:func:`reference_filter`) and a diffuse filter's gains computed once, for its verification, both take."""
    m_inf = inf @ h
    f_inf = h @ m_inf
    if not f_inf > DIFFUSE_TOL * (h @ h) * max(np.max(np.diagonal(inf)), 1.0):
        return None
    k0 = m_inf / f_inf
    a = np.eye(h.size) - np.outer(k0, h)
    # the kappa^0 term of (P_* + kappa P_inf) updated: Joseph form with the diffuse gain K0
    cov = symmetrize(a @ cov @ a.T + np.outer(k0, k0))
    inf = symmetrize(inf - np.outer(m_inf, m_inf) / f_inf)
    return DiffuseStep(k0, cov, None if np.sum(inf * inf) <= DIFFUSE_TOL else inf, float(f_inf))


def predict_diffuse(inf: np.ndarray, phi: np.ndarray) -> np.ndarray | None:
    """P_inf predicted, Phi P_inf Phi^T; None once it counts as 0 (|P_inf|_F^2 <= DIFFUSE_TOL)."""
    inf = symmetrize(phi @ inf @ phi.T)
    return None if np.sum(inf * inf) <= DIFFUSE_TOL else inf


def _update_row(state: _State, white: Whitened, j: int, conditioned: np.ndarray) -> None:
    """The univariate updates of row j's measured components (exact diffuse where F_inf > 0)."""
    for i in range(white.count[j]):
        h = white.hs[j, i]
        e = white.zs[j, i] - h @ state.x
        if state.inf is not None:
            step = diffuse_step(state.cov, state.inf, h)
            if step is not None:
                state.x = state.x + step.gain * e
                state.cov, state.inf, f_inf = step.cov, step.inf, step.f_inf
                conditioned[j, white.origin[j, i]] = True
                # statsmodels' term is -1/2 log(2 pi F_inf) of the component in its own units,
                # F_inf L_ii^2: the decorrelation's Jacobian belongs to it
                state.diffuse_term -= 0.5 * (_LOG_2PI + np.log(f_inf)) + white.log_l[j, i]
                continue
        gain, state.cov, s = gain_and_covariance(state.cov, h[None, :], _ONE, "joseph")
        f = s[0, 0]
        state.x = state.x + gain[:, 0] * e
        state.loglik -= 0.5 * (_LOG_2PI + np.log(f) + e * e / f) + white.log_l[j, i]


def _undetermined(inf: np.ndarray | None, d: int) -> np.ndarray:
    """The states with no finite mean: a nonzero diagonal of P_inf."""
    if inf is None:
        return np.zeros(d, dtype=bool)
    return np.diagonal(inf) > DIFFUSE_TOL


def _diffuse_rows(model, white, gq, bu, arrays, conditioned, stop_when_proper):
    """Run the numpy reference from row 0: every row, or (``stop_when_proper``) until a row's prior is
    proper, writing each row into ``arrays`` (None: the likelihood alone). Returns the state and the row
    reached."""
    state = _State(model)
    d = model.state_dim
    for j in range(model.steps):
        if j > 0:
            _predict(state, model, gq, bu[j - 1])
        if stop_when_proper and state.inf is None:
            return state, j
        if arrays is not None:
            arrays[4][j] = state.inf is None
            arrays[0][j], arrays[1][j] = _masked(state.x, state.cov, _undetermined(state.inf, d))
        _update_row(state, white, j, conditioned)
        if arrays is not None:
            arrays[2][j], arrays[3][j] = _masked(state.x, state.cov, _undetermined(state.inf, d))
    return state, model.steps


def _masked(x, cov, bad):
    x, cov = x.copy(), cov.copy()
    x[bad] = np.nan
    cov[bad] = np.nan
    cov[:, bad] = np.nan
    return x, cov


def _prepare(model: TimeVaryingModel, z):
    z = np.asarray(z, dtype=float)
    measured = measured_components(model, z)
    white = whiten(model, z, measured)
    gq = symmetrize(model.gamma @ model.w @ model.gamma.T)
    bu = np.ascontiguousarray(model.u @ model.b.T)
    return z, measured, white, gq, bu


def _empty(n, d):
    return (np.empty((n, d)), np.empty((n, d, d)), np.empty((n, d)), np.empty((n, d, d)), np.zeros(n, dtype=bool))


def _finish(model, z, measured, arrays, conditioned, loglik_value, diffuse_term) -> TimeVaryingRun:
    """The row diagnostics (r, S, NIS) from the priors, and the run."""
    prior_states, prior_covs, states, covs, proper_prior = arrays
    n, p, d = model.h.shape
    h = np.where(measured[:, :, None], model.h, 0.0)
    residual = np.where(measured, z - np.einsum("jid,jd->ji", h, np.nan_to_num(prior_states)), np.nan)
    s = symmetrize(h @ np.nan_to_num(prior_covs) @ np.swapaxes(h, 1, 2) + model.v)
    s[~measured[:, :, None] | ~measured[:, None, :]] = np.nan
    residual[~proper_prior] = np.nan
    s[~proper_prior] = np.nan
    values = np.full(n, np.nan)
    codes = measured.astype(np.int64) @ (1 << np.arange(p, dtype=np.int64))
    for code in np.unique(codes[proper_prior]):
        rows = np.flatnonzero((codes == code) & proper_prior)
        comps = np.flatnonzero((code >> np.arange(p)) & 1)
        if comps.size:
            values[rows] = nis(residual[np.ix_(rows, comps)], s[np.ix_(rows, comps, comps)])
    proper_post = ~np.any(np.isnan(states), axis=1)
    proper_from = int(np.argmax(proper_post)) if proper_post.any() else n
    return TimeVaryingRun(states, covs, prior_states, prior_covs, residual, s, values, measured, conditioned,
                          float(loglik_value), float(diffuse_term), proper_from)  # fmt: skip


def reference_filter(model: TimeVaryingModel, z: np.ndarray) -> TimeVaryingRun:
    """The numpy reference filter over every row (the equations are in the module docstring).

    Parameters
    ----------
    model : TimeVaryingModel
    z : ndarray, shape (J, p)
        The measurements, in the units of H x; NaN where a component is not measured.

    Returns
    -------
    TimeVaryingRun
    """
    z, measured, white, gq, bu = _prepare(model, z)
    arrays = _empty(model.steps, model.state_dim)
    conditioned = np.zeros(measured.shape, dtype=bool)
    state, _ = _diffuse_rows(model, white, gq, bu, arrays, conditioned, stop_when_proper=False)
    return _finish(model, z, measured, arrays, conditioned, state.loglik, state.diffuse_term)


def _compiled(model: TimeVaryingModel, z: np.ndarray, store: bool):
    z, measured, white, gq, bu = _prepare(model, z)
    n, d = model.steps, model.state_dim
    arrays = _empty(n if store else 0, d)
    conditioned = np.zeros(measured.shape, dtype=bool)
    state, start = _diffuse_rows(model, white, gq, bu, arrays if store else None, conditioned, stop_when_proper=True)
    total = state.loglik
    if start < n:
        arrays[4][start:] = True  # no rows where nothing is stored
        total += run_rows(model.phi, gq, bu, white.hs, white.zs, white.count, white.log_l, start,
                          np.ascontiguousarray(state.x), np.ascontiguousarray(state.cov), store, *arrays[:4])  # fmt: skip
    return z, measured, arrays, conditioned, total, state.diffuse_term


def filter_model(model: TimeVaryingModel, z: np.ndarray) -> TimeVaryingRun:
    """Filter a log: the diffuse period in numpy (:func:`reference_filter`'s rows), the proper rows compiled.

    Parameters
    ----------
    model : TimeVaryingModel
    z : ndarray, shape (J, p)
        NaN where a component is not measured.

    Returns
    -------
    TimeVaryingRun
        Equal to :func:`reference_filter`'s to rounding (tests/core/test_timevarying_filter.py).
    """
    z, measured, arrays, conditioned, total, diffuse_term = _compiled(model, z, store=True)
    return _finish(model, z, measured, arrays, conditioned, total, diffuse_term)


def loglik(model: TimeVaryingModel, z: np.ndarray) -> float:
    """The conditional log-likelihood of a log (natural log), compiled and storing nothing per row.

    The same number as ``filter_model(model, z).loglik``; the density of the components after the
    diffuse period given the ones conditioned on (module docstring). Add the run's ``diffuse_term``
    for statsmodels' exact diffuse ``llf``.
    """
    return float(_compiled(model, z, store=False)[4])


def smooth(run: TimeVaryingRun, model: TimeVaryingModel) -> SmoothedRun:
    """The RTS smoother (:func:`kalcal.core.smoother.rts_smooth`) over the rows from ``run.proper_from``.

    Rows before it (the diffuse period) are NaN: their smoothed values need the exact diffuse smoother,
    which is not implemented. From ``proper_from`` on they are the mean and covariance of x_j given every
    row of the log.

    Parameters
    ----------
    run : TimeVaryingRun
        From :func:`filter_model` or :func:`reference_filter` over ``model``.
    model : TimeVaryingModel

    Returns
    -------
    SmoothedRun
        state (J, d), cov (J, d, d), gain (J - 1, d, d); NaN before ``proper_from``.
    """
    n, d = run.state.shape
    start = run.proper_from
    state, cov, gain = np.full((n, d), np.nan), np.full((n, d, d), np.nan), np.full((max(n - 1, 0), d, d), np.nan)
    if start < n:
        rows = slice(start, n)
        part = rts_smooth(run.state[rows], run.cov[rows], run.prior_state[rows], run.prior_cov[rows],
                          np.broadcast_to(model.phi, (n - start, d, d)))  # fmt: skip
        state[rows], cov[rows], gain[start:] = part.state, part.cov, part.gain
    return SmoothedRun(state, cov, gain)
