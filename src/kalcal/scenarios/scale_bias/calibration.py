"""Calibrate a sensor's scale-factor error and bias against a reference, from one log.

The note's filter runs over the samples in order: theta = [theta1, theta2] with
reference_k = theta1 sensor_k + theta2 + w_k, then a = 1 - 1 / theta1 and b = theta2 / theta1 with
their covariance by the delta method, J P J^T, J = d(a, b) / d(theta1, theta2). A sample whose reference
or sensor value is missing (NaN) is skipped: only the time propagation (Q) is applied.

Observability. A parameter the log does not excite (a sensor that reads a constant: only theta1 z + theta2
is seen, not theta1 and theta2 apart) keeps about the sigma it would have with no data at all,
sqrt(P_0,ii + K Q_ii) after K samples (a ratio of 1.00 for a constant sensor). Where the final posterior
sigma is above ``UNOBSERVABLE_RATIO`` (0.9) times that, near the prior's, the parameter is reported as
unobservable (:meth:`ScaleBiasCalibration.unobservable`). Genuine excited logs, even short or noisy ones,
end well below (0.36 on the default log, 0.56 on a 10 s log, 0.69 on a 5 s one, 0.70 with reference noise 0.5,
0.75 with a quarter of the default amplitude); they learned less, but from the log, and are not flagged.

Consistency. The mean NIS of K model-matched innovations is chi-square(K) / K; outside its two-sided
bounds at ``NIS_CONFIDENCE`` (:meth:`ScaleBiasCalibration.nis_bounds`) the noise settings do not fit the
log and a ``noise-inconsistent`` warning says so (a consistent log is flagged with probability 1%).

Prior. ``prior="settings"`` starts from the filter's prior of a and b (the simulated study's, or a
datasheet's). ``prior="diffuse"`` starts with no information on theta at all (P_0^{-1} = 0, the limit of
N(m, kappa I) as kappa -> infinity): the filter runs in information form until the first samples with two
different sensor readings determine theta (:func:`diffuse_start`), then as before; those samples have no
innovation. A log is calibrated with the diffuse prior unless the user gives one (kalcal.scenarios.scale_bias.job).
With a prior, the data-only (diffuse) estimate is tested against it: with Q = 0 the difference d =
theta_data - m_0 is N(0, P_data + P_0) under the model, so d^T (P_data + P_0 + K Q)^-1 d is chi-square(2);
above its ``CONFLICT_CONFIDENCE`` quantile a ``prior-conflict`` warning says that data and prior disagree.

Limits. The reference and the sensor must lie within ``SIGNAL_LIMIT`` (1e12) of zero in the log's unit:
no physical signal kalcal calibrates comes near it in any unit, while one corrupt cell of 1e300 would
overflow the filter (:func:`calibrate_scale_bias` refuses it, naming the row and column).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kalcal.calibration.plausibility import CalibrationWarning, check_limit
from kalcal.scenarios.scale_bias.observability import (  # noqa: F401 (DIFFUSE_RCOND: this module's before)
    DATA_ONLY_FACTOR,
    DIFFUSE_RCOND,
    TRACKING_CONFIDENCE,
    UNOBSERVABLE_RATIO,
    data_only_information,
)
from kalcal.core.diffuse import diffuse_start as core_diffuse_start
from kalcal.core.steps import nis
from kalcal.errors import DataError
from kalcal.filters.regression import run_regression_filter
from kalcal.scenarios.scale_bias.filter import filter_scale_bias, regressors
from kalcal.scenarios.scale_bias.settings import STATE_NAMES, ScaleBiasScenario
from kalcal.scenarios.scale_bias.theta import scale_bias_from_theta, scale_bias_jacobian
from kalcal.stats.bounds import chi2_mean_bounds
from kalcal.stats.distributions import chi2_ppf, chi2_sf

#: the mean NIS is tested two-sided at this confidence (a consistent log fails with probability 1 - it)
NIS_CONFIDENCE = 0.99
#: largest plausible abs(reference), abs(sensor), in the log's own unit
SIGNAL_LIMIT = 1e12
#: the priors a calibration can start from
PRIORS = ("diffuse", "settings")
#: data and a given prior conflict when their chi-square(2) difference exceeds this quantile
CONFLICT_CONFIDENCE = 0.99


@dataclass(frozen=True)
class ScaleBiasCalibration:
    """The filter's estimates after each of the K samples of a log (signal unit: the log's)."""

    time: np.ndarray  #: s, (K,)
    theta: np.ndarray  #: posterior [theta1 (1), theta2 (signal unit)], (K, 2)
    covariance: np.ndarray  #: posterior P, (K, 2, 2)
    residual: np.ndarray  #: innovations r_k, NaN where skipped, (K,)
    innovation_var: np.ndarray  #: S_k, NaN where skipped, (K,)
    used: np.ndarray  #: whether sample k updated the filter, bool (K,)
    #: sigma of theta1, theta2 with no data after the K samples, sqrt(P_0,ii + K Q_ii), (2,)
    prior_std: np.ndarray | None = None
    prior: str = "settings"  #: "settings" or "diffuse"
    #: samples the diffuse start took to determine theta (0 with the settings' prior)
    start_samples: int = 0
    #: the data-and-prior test with the settings' prior: statistic, pvalue, bound, conflict (None without)
    conflict: dict | None = None
    #: what the log alone tells of theta (:func:`data_only_information`); None where not computed
    data_only: dict | None = None

    @property
    def std_ratio(self) -> np.ndarray:
        """Final sigma / no-data sigma of theta1 and theta2, (2,): near 1 where nothing was learned."""
        return self.std[-1] / self.prior_std

    def unobservable(self, threshold: float = UNOBSERVABLE_RATIO) -> list[str]:
        """The parameters (of theta1, theta2) the log does not determine.

        Judged from the data-only information where it was computed (:func:`data_only_information`): a
        singular one or (both parameters) a sensor that does not track the reference. A log that
        determines theta (nonsingular, tracking) but less sharply than the prior claims is not
        unobservable: :meth:`prior_tighter` names the prior as the cause. Without the data-only
        information, from the final sigma above ``threshold`` times the no-data sigma."""
        ratio_names = [name for name, ratio in zip(STATE_NAMES, self.std_ratio) if ratio > threshold]
        if self.data_only is None:
            return ratio_names
        d = self.data_only
        if d["singular"] or not d["tracks"]:
            return list(STATE_NAMES)
        return []

    def prior_tighter(self, threshold: float = UNOBSERVABLE_RATIO) -> list[str]:
        """The parameters a log determines (data-only information nonsingular, the sensor tracking the
        reference) less sharply than the prior claims: a data-only sigma above ``DATA_ONLY_FACTOR`` prior
        sigmas, or a final sigma above ``threshold`` times the no-data one. Their estimate and sigma lean on
        the prior, which is the cause (a ``prior-dominates`` warning); a prior conflict is still reported."""
        d = self.data_only
        if d is None or d["singular"] or not d["tracks"] or self.prior == "diffuse":  # no prior to be tighter
            return []
        return [
            name for name, weak, ratio in zip(STATE_NAMES, d["weaker_than_prior"], self.std_ratio)
            if weak or ratio > threshold
        ]  # fmt: skip

    def unobservable_cause(self) -> str | None:
        """Why :meth:`unobservable` names parameters, in words (None when it names none)."""
        names = self.unobservable()
        if not names:
            return None
        d = self.data_only
        if d is not None and d["singular"]:
            return (
                f"the log alone does not determine theta (its information matrix is singular, "
                f"reciprocal condition {d['rcond']:.2g}): the sensor reads one value, so only theta1 z + theta2 is seen"
            )
        if d is not None and not d["tracks"]:
            return (
                f"the sensor does not track the reference (the log alone gives theta1 = "
                f"{d['theta'][0]:.3g} +- {d['empirical_std'][0]:.2g}, with the residual scatter the log shows, "
                f"not distinguishable from 0 at {TRACKING_CONFIDENCE:.0%})"
            )
        ratios = ", ".join(f"{name} {ratio:.2f}" for name, ratio in zip(STATE_NAMES, self.std_ratio) if name in names)
        return f"the final sigma is above {UNOBSERVABLE_RATIO:g} of the sigma with no data ({ratios})"

    def nis_bounds(self, confidence: float = NIS_CONFIDENCE) -> tuple[float, float]:
        """Two-sided bounds of the mean NIS of the samples used, chi-square(K) / K, at ``confidence``."""
        k = self.samples_used
        return chi2_mean_bounds(confidence, 1, k, k)

    @property
    def consistent(self) -> bool:
        """Whether the mean NIS lies within :meth:`nis_bounds`: the noise settings fit the log."""
        lower, upper = self.nis_bounds()
        return bool(lower <= self.mean_nis <= upper)

    def warnings(self, source: str = "data") -> list[CalibrationWarning]:
        """An ``unobservable`` warning naming the parameters the log does not determine and why; a
        ``prior-conflict`` one when data and prior disagree; a ``noise-inconsistent`` one when the mean NIS
        is outside its bounds. Beside ``unobservable`` neither of the other two is a cause: the data-only
        estimate that the prior is tested against is not determined, and innovations that the model
        cannot follow are not fixed by the noise settings, so they say so and give no advice of their own."""
        found = []
        names = self.unobservable()
        cause = self.unobservable_cause()
        tighter = self.prior_tighter()
        if tighter:
            d = self.data_only
            parts = "; ".join(
                f"{name}'s data-only sigma {d['std'][i]:.3g} is {d['std'][i] / self.prior_std[i]:.3g} times its prior sigma "
                f"{self.prior_std[i]:.3g}"
                for i, name in enumerate(STATE_NAMES) if name in tighter
            )
            found.append(
                CalibrationWarning(
                    "prior-dominates",
                    f"{source}: the prior (filter.scale_error, filter.bias and their stds) is tighter than this log can "
                    f"tell ({parts}; the log determines theta: the sensor tracks the reference, reciprocal condition "
                    f"{d['rcond']:.2g}), so the {' and '.join(tighter)} estimate and sigma lean on the prior and hold only "
                    "if it is right; loosen the prior (or calibrate with the diffuse one) for the log's own answer",
                )
            )
        if names:
            found.append(
                CalibrationWarning(
                    "unobservable",
                    f"{source}: {' and '.join(names)} unobservable (no excitation): {cause}, so the estimate is the prior's, "
                    "not the log's; the sensor must track the reference and vary over its range (scale_error and bias "
                    "follow from both)",
                )
            )
        if self.conflict is not None and self.conflict["conflict"] and not names:
            c = self.conflict
            found.append(
                CalibrationWarning(
                    "prior-conflict",
                    f"{source}: data and prior disagree: the data-only theta differs from the prior's mean by "
                    f"chi-square {c['statistic']:.4g} (2 degrees of freedom, bound {c['bound']:.4g} at "
                    f"{CONFLICT_CONFIDENCE:.0%}, p = {c['pvalue']:.2g}): check filter.scale_error, filter.bias and their stds",
                )
            )
        if not self.consistent:
            lower, upper = self.nis_bounds()
            measured = (
                f"{source}: mean NIS {self.mean_nis:.4g} is outside its {NIS_CONFIDENCE:.0%} bounds "
                f"[{lower:.4g}, {upper:.4g}] for {self.samples_used} samples"
            )
            advice = (
                ": the model cannot follow a reference that the sensor does not determine (the unobservable "
                f"{' and '.join(names)} above), which no noise setting mends"
                if names
                else ": the noise settings do not fit the log (set filter.reference_noise_std / sensor_noise_std), "
                "so the sigmas are not to be trusted"
            )
            found.append(CalibrationWarning("noise-inconsistent", measured + advice))
        return found

    @property
    def std(self) -> np.ndarray:
        """1-sigma of theta1 and theta2 from P, (K, 2)."""
        return np.sqrt(np.diagonal(self.covariance, axis1=1, axis2=2))

    @property
    def samples_used(self) -> int:
        return int(np.count_nonzero(self.used))

    def scale_bias(self) -> tuple[float, float, np.ndarray]:
        """a, b and their 2 x 2 covariance (delta method) from the final theta and P."""
        theta, cov = self.theta[-1], self.covariance[-1]
        a, b = scale_bias_from_theta(theta)
        jac = scale_bias_jacobian(theta)
        ab_cov = jac @ cov @ jac.T
        return float(a), float(b), 0.5 * (ab_cov + ab_cov.T)

    @property
    def mean_nis(self) -> float:
        """The mean of r_k^2 / S_k over the samples used: about 1 when the noise settings fit the log."""
        used = self.used
        return float(np.mean(nis(self.residual[used, None], self.innovation_var[used, None, None])))


def diffuse_start(scenario: ScaleBiasScenario, reference: np.ndarray, sensor: np.ndarray):
    """The filter from a diffuse prior, in information form, until theta is determined.

    The information filter's start of :func:`kalcal.core.diffuse.diffuse_start` with h_k = [z_k, 1], the
    filter's R and Q: Y^- = (I + Q Y)^{-1} Y, Y += h h^T / R, until det(Y) > DIFFUSE_RCOND trace(Y)^2; a
    sample with a missing reference or sensor value is a prediction only.

    Returns
    -------
    (m, x, P) : the number of samples taken, x_m^+ and P_m^+ = Y^{-1}; None when the log never determines
    theta (a sensor that reads one value).
    """
    start = core_diffuse_start(
        reference, regressors(sensor), scenario.filter_noise_variance(), scenario.filter_process_noise(), DIFFUSE_RCOND
    )
    return None if start is None else tuple(start)


def _diffuse_run(scenario: ScaleBiasScenario, reference: np.ndarray, sensor: np.ndarray, source: str):
    """The filter over the log from a diffuse prior (NaN estimates while theta is not yet determined)."""
    start = diffuse_start(scenario, reference, sensor)
    if start is None:
        raise DataError(
            f"{source}: the log never determines theta from a diffuse prior: the sensor must take two different "
            "values (or give a prior: --prior settings with filter.scale_error, filter.bias and their stds)"
        )
    m, x, cov = start
    k = reference.size
    rest = run_regression_filter(
        reference[m:], regressors(sensor[m:]), x, cov, scenario.filter_noise_variance(), scenario.filter_process_noise(),
        scenario.filter_settings.form,
    )
    posterior, covs = np.full((k, 2), np.nan), np.full((k, 2, 2), np.nan)
    residual, innovation, used = np.full(k, np.nan), np.full(k, np.nan), np.zeros(k, dtype=bool)
    posterior[m - 1], covs[m - 1] = x, cov
    posterior[m:], covs[m:], residual[m:], innovation[m:], used[m:] = (
        rest.posterior, rest.cov, rest.residual, rest.innovation_var, rest.used,
    )
    return m, posterior, covs, residual, innovation, used


def _conflict(scenario: ScaleBiasScenario, data_theta: np.ndarray, data_cov: np.ndarray, samples: int) -> dict:
    """d^T (P_data + P_0 + K Q)^-1 d with d = theta_data - m_0: chi-square(2) when data and prior agree."""
    prior = scenario.filter_prior()
    d = data_theta - prior.mean
    statistic = float(d @ np.linalg.solve(data_cov + prior.cov + samples * scenario.filter_process_noise(), d))
    bound = float(chi2_ppf(CONFLICT_CONFIDENCE, 2))
    return {"statistic": statistic, "pvalue": float(chi2_sf(statistic, 2)), "bound": bound,
            "confidence": CONFLICT_CONFIDENCE, "conflict": statistic > bound}


def calibrate_scale_bias(
    scenario: ScaleBiasScenario,
    time: np.ndarray,
    reference: np.ndarray,
    sensor: np.ndarray,
    *,
    source: str = "data",
    columns: tuple[str, str] = ("reference", "sensor"),
    prior: str = "settings",
    conflict: bool = False,
) -> ScaleBiasCalibration:
    """Run the filter (``filter`` settings of ``scenario``) over one log.

    Parameters
    ----------
    scenario : ScaleBiasScenario
        Its ``filter`` settings give the prior, the noise, Q and the update form.
    time : ndarray, shape (K,)
        Sample times, s (labels only: Q applies per sample).
    reference, sensor : ndarray, shape (K,)
        v_k and z_k in the signal's unit; NaN marks a missing value.
    source : str
        The log's name, quoted in errors.
    columns : (str, str)
        The log's reference and sensor columns, quoted in errors.
    prior : {"settings", "diffuse"}
        Start from the filter's prior of a and b, or from no information on theta (module docstring);
    conflict : bool
        With "settings", test the data-only estimate against the prior (``conflict`` of the result, and a
        ``prior-conflict`` warning when they disagree).

    Raises
    ------
    DataError
        When a value is beyond ``SIGNAL_LIMIT`` (naming the row and column), when no sample has both values, or the final theta1 is not positive (the sensor does not follow
        the reference, so a = 1 - 1 / theta1 means nothing).
    """
    reference = np.asarray(reference, dtype=float)
    sensor = np.asarray(sensor, dtype=float)
    for values, column in zip((reference, sensor), columns):
        check_limit(values, "signal", source, column, limit=SIGNAL_LIMIT, unit=scenario.scenario.unit)
    if not np.any(np.isfinite(reference) & np.isfinite(sensor)):
        raise DataError(f"{source}: no sample has both a reference and a sensor value")
    if prior not in PRIORS:
        raise DataError(f"--prior: expected one of {', '.join(PRIORS)}, got {prior!r}")
    if prior == "diffuse":
        m, posterior, covs, residual, innovation, used = _diffuse_run(scenario, reference, sensor, source)
        result = ScaleBiasCalibration(
            time=np.asarray(time, dtype=float), theta=posterior, covariance=covs, residual=residual,
            innovation_var=innovation, used=used, prior_std=np.full(2, np.inf), prior="diffuse", start_samples=m,
        )
    else:
        run = filter_scale_bias(scenario, reference, sensor)
        found = None
        if conflict and diffuse_start(scenario, reference, sensor) is not None:
            data = _diffuse_run(scenario, reference, sensor, source)
            found = _conflict(scenario, data[1][-1], data[2][-1], reference.size)
        result = ScaleBiasCalibration(
            time=np.asarray(time, dtype=float),
            theta=run.posterior,
            covariance=run.cov,
            residual=run.residual,
            innovation_var=run.innovation_var,
            used=run.used,
            prior_std=np.sqrt(np.diag(scenario.filter_prior().cov + reference.size * scenario.filter_process_noise())),
            conflict=found,
        )
    data_only = data_only_information(reference, sensor, scenario.filter_noise_variance())
    if prior != "diffuse":
        data_only["weaker_than_prior"] = [bool(s > DATA_ONLY_FACTOR * p) for s, p in zip(data_only["std"], result.prior_std)]
    from dataclasses import replace

    result = replace(result, data_only=data_only)
    theta1 = float(result.theta[-1, 0])
    if not theta1 > 0:
        raise DataError(
            f"{source}: the estimated theta1 = {theta1:.6g} is not positive: the sensor does not follow the "
            "reference (swapped or inverted columns?)"
        )
    return result
