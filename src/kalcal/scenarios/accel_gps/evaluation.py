"""One evaluation of a prepared accelerometer/GPS log: its settings resolved, the filter's inputs built, the run.

Everything here is O(fixes): the pieces' composition was done once by
:func:`~kalcal.scenarios.accel_gps.log.prepare_accel_gps_log`; an evaluation scales the per-source
noise (Q_k = sigma_a^2 Q_k^a + bias_walk_std^2 Q_k^w + bias_std^2 Q_k^m), corrects the transition and the
bias noise for a changed ``bias_correlation_time`` (:func:`continuous_terms`), moves the comparison to
t - latency, and runs the compiled filter.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from kalcal.scenarios.accel_gps.interval_model import continuous_bias_model
from kalcal.core.sqrt_form import cholesky_factor, gram, sqrt_predict, sqrt_update
from kalcal.core.steps import UpdateForm, nis, predict, update
from kalcal.filters.sequential import SequentialRun, sequential_filter
from kalcal.models.settings import SettingError, show, to_float
from kalcal.stats.distributions import chi2_ppf  # scipy.stats's values, without its import

if TYPE_CHECKING:
    from kalcal.scenarios.accel_gps.log import AccelGpsLog

#: the settings an evaluation may override, and their units
UNITS: dict[str, str] = {
    "filter.accel_noise_std": "m/s^2",
    "filter.bias_walk_std": "m/s^2",
    "filter.gps_position_std": "m",
    "filter.gps_velocity_std": "m/s",
    "filter.bias_std": "m/s^2",
    "filter.bias_correlation_time": "s",
    "filter.position0_std": "m",
    "filter.velocity0_std": "m/s",
    "filter.scale_std": "1",
    "filter.gps_latency": "s",
    "log.position_std_multiplier": "1",
    "log.velocity_std_multiplier": "1",
}
_POSITIVE = ("filter.accel_noise_std", "filter.gps_position_std", "filter.gps_velocity_std", "filter.bias_std",
             "filter.position0_std", "filter.velocity0_std", "log.position_std_multiplier", "log.velocity_std_multiplier")
#: the keys of the position fix alone: a log of velocity-only fixes has none of them
POSITION_FIX_KEYS = frozenset({"filter.gps_position_std", "log.position_std_multiplier"})
_NONNEGATIVE = ("filter.bias_walk_std", "filter.bias_correlation_time", "filter.scale_std")
#: the bias's prior 1-sigma that stands for "diffuse", m/s^2 (100 g: no accelerometer's bias comes near;
#: its effect on the estimates after the first fix is of order (sigma_1 / 1000)^2, sigma_1 the bias's
#: 1-sigma after that fix)
DIFFUSE_BIAS_STD = 1000.0


def resolve(log: AccelGpsLog, values: Mapping[str, Any]) -> dict[str, float]:
    """Every key of :data:`UNITS` -> its value: the log's settings with ``values`` over them (SettingError
    naming an unknown or out-of-range key)."""
    resolved = {key: log.settings_value(key) for key in UNITS if key in log.available_keys()}
    for key, value in values.items():
        if key not in UNITS:
            raise SettingError(key, f"a setting of the accel-gps likelihood ({', '.join(UNITS)})", "an unknown key")
        if key in POSITION_FIX_KEYS and 0 not in log.fix_states:
            raise SettingError(key, 'a setting the fixes use (velocity-only fixes, scenario.gps_fixes = "velocity", have no position)', show(value))
        if key not in resolved:
            raise SettingError(key, "a multiplier of a per-fix std column that the GPS log has", "a log without that column")
        number = to_float(key, value)
        if key in _POSITIVE and not number > 0:
            raise SettingError(key, "a positive number", show(value))
        if key in _NONNEGATIVE and not number >= 0:
            raise SettingError(key, "zero or a positive number", show(value))
        resolved[key] = number
    return resolved


class FilterInputs(NamedTuple):
    """What the filter runs on: per-fix models, the measurements, the prior, and the nominal compared."""

    phis: np.ndarray  #: (K, d, d)
    qs: np.ndarray  #: (K, d, d)
    h: np.ndarray  #: (p, d): p = 2 (position, velocity) or 1 (velocity-only fixes)
    vs: np.ndarray  #: (K, p, p)
    dz: np.ndarray  #: (K, p)
    x0: np.ndarray  #: (d,)
    m0: np.ndarray  #: (d, d)
    nominal_p: np.ndarray  #: p_c at each fix's stamp (where the state is estimated), m, (K,)
    nominal_v: np.ndarray  #: v_c there, m/s, (K,)
    bias_prior_std: float  #: m/s^2


def continuous_terms(log: AccelGpsLog, tau: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The change of the bias column of Phi_k and of Q_k^w, Q_k^m when tau differs from the log's tau_0.

    The log holds the exact per-sample composition at tau_0. A new tau adds the difference between the
    continuous-time model's terms at tau and at tau_0 over each interval
    (:func:`~kalcal.scenarios.accel_gps.interval_model.continuous_bias_model`): exact at tau = tau_0, and
    elsewhere off from the exact per-sample composition by the continuous model's own discretization
    difference times the relative change, of order dt / tau (a sample period over the correlation time).
    """
    column, integral = continuous_bias_model(log.spans, tau)
    column0, integral0 = continuous_bias_model(log.spans, log.settings.bias_correlation_time)
    rate, rate0 = (1.0 / tau if tau > 0 else 0.0), (1.0 / log.settings.bias_correlation_time if log.settings.bias_correlation_time > 0 else 0.0)
    return column - column0, (integral - integral0) / log.period, 2.0 * rate * integral - 2.0 * rate0 * integral0


def latency_map(latency: float) -> tuple[np.ndarray, np.ndarray]:
    """H_L, the fix's error [dp, dv](t - L) from the state at t, and Phi_L from t - L to t (3 states).

    Exact for the error model's deterministic part with the bias constant over L (dv' = -b), for both
    schemes; the accelerometer noise between t - L and t and a Gauss-Markov bias's decay over L are left
    out (of order sigma_a^2 L / dt against the fix's noise, and L / tau).
    """
    lat = latency
    h = np.array([[1.0, -lat, -0.5 * lat * lat], [0.0, 1.0, lat]])
    phi = np.array([[1.0, lat, -0.5 * lat * lat], [0.0, 1.0, -lat], [0.0, 0.0, 1.0]])
    return h, phi


def build_inputs(log: AccelGpsLog, v: Mapping[str, float], overridden=()) -> FilterInputs:
    """The filter's inputs for the resolved settings ``v`` (:func:`resolve`); ``overridden`` names the
    keys the evaluation set (a ``filter.bias_std`` among them replaces a diffuse bias prior)."""
    tau, lat = v["filter.bias_correlation_time"], v["filter.gps_latency"]
    phis, sources = log.phis, log.sources
    q_walk, q_markov = sources[1], sources[2]
    if tau != log.settings.bias_correlation_time:
        d_column, d_walk, d_markov = continuous_terms(log, tau)
        phis = phis.copy()
        phis[:, :, 2] += d_column
        q_walk, q_markov = q_walk + d_walk, q_markov + d_markov
    qs = v["filter.accel_noise_std"] ** 2 * sources[0] + v["filter.bias_walk_std"] ** 2 * q_walk + v["filter.bias_std"] ** 2 * q_markov
    nominal_p, nominal_v, stamp_p, stamp_v = log.nominal(lat)
    rows = list(log.fix_states)  # the components the fixes measure: [0, 1], or [1] for velocity alone
    velocity_only = 0 not in rows
    dz = np.stack([log.z_position - nominal_p, log.z_velocity - nominal_v], axis=1)[:, rows]
    # a velocity-only log has no position std: a placeholder for the row that is dropped
    std_p = 1.0 if velocity_only else log.fix_std("position", v.get("log.position_std_multiplier", 1.0), v["filter.gps_position_std"])
    std_v = log.fix_std("velocity", v.get("log.velocity_std_multiplier", 1.0), v["filter.gps_velocity_std"])
    vs = np.zeros((dz.shape[0], 2, 2))
    vs[:, 0, 0], vs[:, 1, 1] = std_p**2, std_v**2
    vs = vs[:, rows][:, :, rows]
    diffuse = log.prior == "diffuse" and tau == 0 and "filter.bias_std" not in overridden
    bias0 = DIFFUSE_BIAS_STD if diffuse else v["filter.bias_std"]
    h, phi_lat = latency_map(lat)
    h = h[rows]
    if log.init == "first-fix":
        # a velocity-only first fix gives no position: the position starts from the prior's 1-sigma
        first = log.first_std(v.get("log.position_std_multiplier", 1.0), v.get("log.velocity_std_multiplier", 1.0),
                              v["filter.position0_std"] if velocity_only else v["filter.gps_position_std"],
                              v["filter.gps_velocity_std"])
        m0 = np.diag([first[0] ** 2, first[1] ** 2, bias0**2])
        if lat != 0.0:  # the first fix describes t_0 - L; the filter starts at t_0
            m0 = phi_lat @ m0 @ phi_lat.T
    else:
        m0 = np.diag([v["filter.position0_std"] ** 2, v["filter.velocity0_std"] ** 2, bias0**2])
    x0 = np.zeros(3)
    if v["filter.scale_std"] > 0:
        phis, qs = np.pad(phis, ((0, 0), (0, 1), (0, 1))), np.pad(qs, ((0, 0), (0, 1), (0, 1)))
        phis[:, 3, 3] = 1.0
        phis[:, 0, 3], phis[:, 1, 3] = log.scale_columns[:, 0], log.scale_columns[:, 1]
        h, x0 = np.pad(h, ((0, 0), (0, 1))), np.zeros(4)
        m0 = np.pad(m0, ((0, 1), (0, 1)))
        m0[3, 3] = v["filter.scale_std"] ** 2
    return FilterInputs(phis, qs, h, vs, dz, x0, m0, stamp_p, stamp_v, float(bias0))


def gate_threshold(gate: float | None, p: int = 2) -> float | None:
    """chi2.ppf(gate, p), the NIS above which a fix is rejected; None for no gate."""
    if gate is None:
        return None
    if not (isinstance(gate, (int, float)) and not isinstance(gate, bool) and 0 < gate < 1):
        raise SettingError("--gate", "a confidence between 0 and 1 (e.g. 0.999)", show(gate))
    return float(chi2_ppf(gate, p))


def run_filter(inputs: FilterInputs, form: UpdateForm, threshold: float | None) -> tuple[SequentialRun, np.ndarray]:
    """The filter over the inputs (compiled for Joseph, numpy loops for the other forms) and its rejections."""
    phis, qs, h, vs, dz, x0, m0 = inputs[:7]
    rejected = np.zeros(dz.shape[0], dtype=bool)
    if form == "joseph":
        return sequential_filter(phis, qs, h, vs, dz, x0, m0, threshold=threshold, rejected=rejected), rejected
    return python_filter(phis, qs, h, vs, dz, x0, m0, form, threshold, rejected), rejected


def python_filter(phis, noise, h, v, dz, x0, m0, form: UpdateForm, threshold=None, rejected=None) -> SequentialRun:
    """The same filter with :func:`predict` and :func:`update` (or, for form "sqrt", :func:`sqrt_predict`
    and :func:`sqrt_update` carrying a factor of P), one fix at a time, with the same gate."""
    (n_fixes, p), d = dz.shape, x0.shape[0]
    states, covariances = np.empty((n_fixes, d)), np.empty((n_fixes, d, d))
    residuals, innovations = np.empty((n_fixes, p)), np.empty((n_fixes, p, p))
    prior_states, prior_covariances = np.empty((n_fixes, d)), np.empty((n_fixes, d, d))
    x, cov = x0, m0
    if form == "sqrt":
        chol, noise_chol, v_chol = cholesky_factor(m0), cholesky_factor(noise), cholesky_factor(v)
    for k in range(n_fixes):
        if form == "sqrt":
            x, chol = sqrt_predict(x, chol, phis[k], noise_chol[k])
            prior_states[k], prior_covariances[k] = x, gram(chol)
            result = sqrt_update(x, chol, dz[k], h, v_chol[k])
            innovation = gram(result.innovation_chol)
        else:
            x, cov = predict(x, cov, phis[k], noise[k])
            prior_states[k], prior_covariances[k] = x, cov
            result = update(x, cov, dz[k], h, v[k], form)
            innovation = result.innovation_cov
        residual = result.residual
        if threshold is not None and nis(residual, innovation) > threshold:
            rejected[k] = True  # a prediction only: x, cov (chol) stay the prior's
            cov = prior_covariances[k]
        elif form == "sqrt":
            x, chol = result.x, result.chol
            cov = gram(chol)
        else:
            x, cov = result.x, result.cov
        states[k], covariances[k], residuals[k], innovations[k] = x, cov, residual, innovation
    return SequentialRun(states, covariances, residuals, innovations, prior_states, prior_covariances)
