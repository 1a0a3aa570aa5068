"""The bias sigma over the noise settings a log cannot reject, beside the one conditional on the settings.

A calibration's sigma sqrt(P_bb) holds only if the filter's noise settings are right. On a short log they
may be barely identifiable: over 30 s a random walk in velocity (accelerometer noise) looks like a bias,
so a log cannot tell an ``accel_noise_std`` of 0.02 from 0.2 m/s^2 per sample, while the bias's error is
about 5 times larger at 0.2. This module reports the largest error sigma of the reported bias over the
settings the log cannot reject:

1. **The region.** The noise settings the filter's model has (``filter.accel_noise_std``, the GPS stds or
   the multipliers of a GPS log's per-fix std columns, and ``filter.bias_walk_std`` where the filter has a
   walk) are fitted by maximum likelihood as ``kalcal fit`` fits them (:func:`kalcal.fitting.mle.maximize`
   over the same log-likelihood :meth:`~kalcal.scenarios.accel_gps.log.AccelGpsLog.loglik`, the same
   search ranges). The region is every setting whose log L lies within drop = chi2.ppf(confidence, 1) / 2
   of the maximum (1.92 at 0.95): the set whose boundary gives the fit's own intervals, and, for one
   function of the settings, the profile-likelihood interval of that function at ``confidence``. A walk
   the filter does not model is not freed: whether the bias drifts is a question about the model, which
   the stability test and ``kalcal fit``'s adequacy answer (a walk that a 30 s log cannot reject makes
   the last bias 15 to 70 times less certain, which says nothing about a constant bias).
2. **The sigma at each setting.** Under settings theta the true errors follow the filter's model with
   theta's noise, while the reported estimate is the one of the filter's gains K_k (the filter's own
   settings). Its error is linear in the noises, e_K = sum_k R_k [(I - K_k H) w_k - K_k v_k] + R_0 e_0
   (R_k the bias row of the error's transition from fix k to the last), so its variance is
   c_0 + sum_s theta_s^2 c_s: one backward pass over the fixes gives each source's coefficient c_s
   (:func:`error_variance_terms`), and at the filter's own settings the sum is P_bb exactly (the tests).
   This is the actual error of the estimate the table reports, not the sigma another filter would claim.
3. **The largest** sqrt(c_0 + sum theta_s^2 c_s) over the region (SLSQP from the maximum, in log
   values), and never below the conditional sigma: ``bias_std`` = max(that, sqrt(P_bb)).

Chosen over integrating the settings out (a posterior mean of the variance needs a prior on the settings,
and a flat likelihood toward 0, as the accelerometer noise's on a short log, hands the answer to that
prior) and over the largest sigma on the box of the marginal intervals (whose corner the log may reject).

Cost: one maximum-likelihood search of 3 settings (without the intervals' curves) and one constrained
search, some hundreds of O(fixes) filter runs: about 0.2-0.9 s on the default 30 s log (a calibration
alone: 0.01 s), about what ``kalcal fit`` costs on a long log.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from kalcal.calibration.plausibility import CalibrationWarning
from kalcal.scenarios.accel_gps import evaluation

__all__ = [
    "CONFIDENCE", "SETTINGS_DEPENDENT", "WARN_FACTOR", "SettingsSigma", "error_variance_terms", "settings_free",
    "settings_sigma", "settings_warning",
]

#: the confidence of the region of settings the log cannot reject (``kalcal fit``'s intervals' own)
CONFIDENCE = 0.95
#: the code of the warning that the bias sigma depends on the noise settings
SETTINGS_DEPENDENT = "sigma-depends-on-settings"
#: a settings sigma more than this many times the conditional one is a warning. On the default 30 s
#: scenario with the right settings the ratio is 4.7 (median), 7.2 (90%) and at most 11.0 over 100
#: simulated logs (seeds 100-199), because that log cannot pin the accelerometer noise down; with 10 times
#: the filter's accelerometer noise its median is 11.8 and 48% of 60 logs exceed 12: no factor tells the
#: two apart on such a log, only the sigma itself is safe
WARN_FACTOR = 12.0
#: the settings whose variance enters the error linearly, each a source of :func:`error_variance_terms`
SOURCES = (
    "filter.accel_noise_std",
    "filter.bias_walk_std",
    "filter.bias_std",
    "filter.gps_position_std",
    "filter.gps_velocity_std",
    "log.position_std_multiplier",
    "log.velocity_std_multiplier",
)


@dataclass(frozen=True)
class SettingsSigma:
    """The bias's 1-sigma over the noise settings the log cannot reject (m/s^2), beside the conditional one.

    Attributes
    ----------
    bias_std : float
        max(conditional_bias_std, the largest error sigma of the reported bias over the region), m/s^2.
    conditional_bias_std : float
        sqrt(P_bb) at the last fix: the sigma if the filter's noise settings are right, m/s^2.
    ratio : float
        bias_std / conditional_bias_std (>= 1).
    factor : float
        The ratio above which ``warns`` (:data:`WARN_FACTOR`).
    confidence : float
        The region's confidence: log L within chi2.ppf(confidence, 1) / 2 of its maximum.
    free : tuple of str
        The settings varied.
    at : dict
        The settings where the largest sigma is reached, each in its unit.
    fitted : dict
        The settings' maximum-likelihood estimates.
    filter_rejected : bool
        Whether the filter's own settings lie outside the region (the log rejects them).
    """

    bias_std: float
    conditional_bias_std: float
    ratio: float
    factor: float
    confidence: float
    free: tuple[str, ...]
    at: dict[str, float] = field(default_factory=dict)
    fitted: dict[str, float] = field(default_factory=dict)
    filter_rejected: bool = False

    @property
    def warns(self) -> bool:
        """Whether the two sigmas differ by more than ``factor``."""
        return self.ratio > self.factor

    def as_dict(self) -> dict[str, Any]:
        return {
            "bias_std": self.bias_std,
            "conditional_bias_std": self.conditional_bias_std,
            "ratio": self.ratio,
            "factor": self.factor,
            "warns": self.warns,
            "confidence": self.confidence,
            "method": "largest error sigma of the reported bias over the settings within the likelihood region",
            "free": list(self.free),
            "at": dict(self.at),
            "fitted": dict(self.fitted),
            "filter_rejected": self.filter_rejected,
        }


def settings_free(log) -> list[str]:
    """The noise settings of the filter's model: the accelerometer's, each GPS std (a multiplier of a
    per-fix std column where the log has one), and the bias walk's where the filter has a walk."""
    free = ["filter.accel_noise_std"]
    for kind in [("position", "velocity")[i] for i in log.fix_states]:
        free.append(f"log.{kind}_std_multiplier" if log.has_column[kind] else f"filter.gps_{kind}_std")
    if log.settings_value("filter.bias_walk_std") > 0:
        free.append("filter.bias_walk_std")
    return free


def error_variance_terms(log, calibration, values: Mapping[str, float] | None = None) -> tuple[float, dict[str, float]]:
    """The reported last bias's error variance under any noise settings theta: c_0 + sum_s theta_s^2 c_s.

    Parameters
    ----------
    log : AccelGpsLog
        The prepared log.
    calibration : AccelGpsCalibration
        ``log.calibrate(values)``: the filter whose gains made the estimate (its prior covariances M_k,
        innovation covariances S_k and rejected fixes).
    values : mapping, optional
        The settings that calibration ran with, over the log's.

    Returns
    -------
    (float, dict)
        c_0 (m^2/s^4: the settings not among :data:`SOURCES`, such as the position and velocity priors) and
        ``{source: c_s}`` (m^2/s^4 per unit of the setting's variance) for each source the log has.
    """
    values = dict(values or {})
    resolved = evaluation.resolve(log, values)
    inputs = evaluation.build_inputs(log, resolved, set(values))
    h, phis = inputs.h, inputs.phis
    d = phis.shape[1]
    prior, innovation = calibration.prior_covariance, calibration.innovation_cov
    # K_k = M_k H^T S_k^-1, by a solve with S_k (symmetric); a rejected fix was a prediction only
    gain = np.swapaxes(np.linalg.solve(innovation, np.swapaxes(prior @ h.T, 1, 2)), 1, 2)
    if calibration.rejected is not None:
        gain[np.asarray(calibration.rejected, dtype=bool)] = 0.0
    keep = np.eye(d) - gain @ h
    carry = keep @ phis  # e_k = (I - K_k H) Phi_k e_{k-1} + (I - K_k H) w_k - K_k v_k
    row = np.zeros(d)
    row[2] = 1.0
    if d == 4:  # the filter's b' = b / (1 + s) and s' (interval_model.scale_parameters): b's row, the delta method's
        b_prime, s_prime = calibration.filter_state[-1, 2], calibration.filter_state[-1, 3]
        row = np.array([0.0, 0.0, 1.0 / (1.0 - s_prime), b_prime / (1.0 - s_prime) ** 2])
    n = phis.shape[0]
    rows = np.empty((n + 1, d))  # rows[k]: the last bias's row of the error's transition from fix k
    rows[n] = row
    for k in range(n - 1, -1, -1):
        rows[k] = rows[k + 1] @ carry[k]
    a = np.einsum("kd,kde->ke", rows[1:], keep)
    b = np.einsum("kd,kdp->kp", rows[1:], gain)

    def variance(inp) -> float:
        return float(np.einsum("kd,kde,ke->", a, inp.qs, a) + np.einsum("kp,kpq,kq->", b, inp.vs, b)
                     + rows[0] @ inp.m0 @ rows[0])

    present = [key for key in SOURCES if key in resolved]
    zero = {**resolved, **{key: 0.0 for key in present}}
    base = variance(evaluation.build_inputs(log, zero, set(values)))
    coefficients = {key: variance(evaluation.build_inputs(log, {**zero, key: 1.0}, set(values))) - base for key in present}
    return base, coefficients


def _variance(base: float, coefficients: Mapping[str, float], resolved: Mapping[str, float], over: Mapping[str, float]) -> float:
    return base + sum(c * float(over.get(key, resolved[key])) ** 2 for key, c in coefficients.items())


def settings_sigma(log, calibration, *, gate: float | None = None, confidence: float = CONFIDENCE,
                   free: Sequence[str] | None = None) -> SettingsSigma:
    """The bias's sigma over the noise settings ``log`` cannot reject (the module's docstring).

    Parameters
    ----------
    log : AccelGpsLog
    calibration : AccelGpsCalibration
        ``log.calibrate(gate=gate)``, whose last bias is the one reported.
    gate : float, optional
        The calibration's gate: its rejected fixes are held left out of every evaluation of log L.
    confidence : float
        Of the region, in (0, 1).
    free : sequence of str, optional
        The settings varied (default :func:`settings_free`).
    """
    from scipy import optimize

    from kalcal.scenarios.accel_gps.fit import FLOORS, RANGE
    from kalcal.fitting.mle import Free, drop_of, guarded, maximize

    free = list(settings_free(log) if free is None else free)
    rejected = None if gate is None else np.asarray(calibration.rejected, dtype=bool)

    def loglik(values: Mapping[str, float]) -> float:
        return log.loglik(values) if rejected is None else log.loglik(values, rejected=rejected)

    parameters = []
    for key in free:
        value = log.settings_value(key)
        start = value if value > 0 else FLOORS.get(key, 1e-6)
        parameters.append(Free(key, start, start / RANGE, start * RANGE, log.unit(key)))
    fit = maximize(loglik, parameters, confidence=confidence, curve_points=1)
    base, coefficients = error_variance_terms(log, calibration)
    resolved = evaluation.resolve(log, {})
    conditional = float(np.sqrt(calibration.covariance[-1, 2, 2]))
    level = fit.loglik - drop_of(confidence)
    low = np.log([p.lower for p in parameters])
    high = np.log([p.upper for p in parameters])
    u_hat = np.clip(np.log([fit.values[key] for key in free]), low, high)
    best = {"u": u_hat, "variance": _variance(base, coefficients, resolved, fit.values)}

    def at(u: np.ndarray) -> dict[str, float]:
        return dict(zip(free, np.exp(u).tolist()))

    def objective(u: np.ndarray) -> float:
        return -np.log(max(_variance(base, coefficients, resolved, at(u)), 1e-300))

    def constraint(u: np.ndarray) -> float:
        margin = guarded(loglik, at(u)) - level
        variance = _variance(base, coefficients, resolved, at(u))
        if margin >= 0 and variance > best["variance"]:  # the largest feasible point met, whatever SLSQP returns
            best.update(u=np.array(u, dtype=float), variance=variance)
        return margin

    # The variance grows with theta^2, so its gradient in log theta vanishes where the maximum puts a
    # setting at its range's floor (an accelerometer noise consistent with 0): a search from there alone
    # can stay there. It starts from the filter's settings too, and the largest feasible point is kept.
    u_filter = np.clip(np.log([max(resolved[key], p.lower) for key, p in zip(free, parameters)]), low, high)
    for start in (u_filter, u_hat):
        optimize.minimize(objective, start, method="SLSQP", bounds=list(zip(low, high)),
                          constraints=[{"type": "ineq", "fun": constraint}], options={"maxiter": 200, "ftol": 1e-10})
    largest = float(np.sqrt(best["variance"]))
    sigma = max(largest, conditional)
    return SettingsSigma(
        bias_std=sigma,
        conditional_bias_std=conditional,
        ratio=sigma / conditional,
        factor=WARN_FACTOR,
        confidence=confidence,
        free=tuple(free),
        at=at(best["u"]) if largest >= conditional else {key: float(resolved[key]) for key in free},
        fitted={key: float(fit.values[key]) for key in free},
        filter_rejected=bool(loglik({}) < level),
    )


def settings_warning(over: SettingsSigma) -> CalibrationWarning:
    """The ``sigma-depends-on-settings`` warning: the sigma over the settings the log cannot reject is more
    than the factor times the conditional one."""
    at = ", ".join(f"{key} {value:.3g}" for key, value in over.at.items())
    return CalibrationWarning(
        SETTINGS_DEPENDENT,
        f"the bias 1-sigma {over.conditional_bias_std:.3g} m/s^2 holds only if the noise settings are right: over "
        f"the settings this log cannot reject (log L within the {over.confidence:g} region) it reaches "
        f"{over.bias_std:.3g} m/s^2, {over.ratio:.3g} times as large (at {at}); report that one, or pin the settings "
        "down with a longer or livelier log (`kalcal fit`)",
    )
