"""Verification problems for the built-in scenarios and for model files (custom linear models)."""

from __future__ import annotations

from functools import partial

import numpy as np

from kalcal.core.model import LinearGaussianModel
from kalcal.core.steps import UpdateForm, interval_transition
from kalcal.errors import ConfigError
from kalcal.scenarios.accel_gps.settings import MEASUREMENT_NAMES, MEASUREMENT_UNITS, AccelGpsScenario
from kalcal.scenarios.model_file.model import CustomModelScenario
from kalcal.scenarios.scale_bias.settings import ScaleBiasScenario
from kalcal.models.settings import SettingError, show
from kalcal.montecarlo.problem import FixedGainProblem, Problem, ProblemInfo
from kalcal.scenarios.scale_bias.problem import ScaleBiasProblem, model_error_cause
from kalcal.simulation.exact import accel_gps_transitions, accel_gps_truth, truth_from_model
from kalcal.scenarios.accel_gps.sampled import sample_accel_gps_errors


def sampled_normals_per_realization(scenario: AccelGpsScenario) -> int:
    """Normals the per-sample engine draws: p0, v0, b, sample 0 (and s); per interval m samples and 2 fix
    noises (and m bias-noise draws when the bias drifts). See :mod:`kalcal.scenarios.accel_gps.sampled`."""
    s = scenario.scenario
    m = s.steps_per_update
    drifts = scenario.truth.bias_step_variance(s.sample_period) > 0
    return 4 + int(scenario.has_scale) + s.n_updates * (m + 2 + (m if drifts else 0))


def accel_gps_filter_transitions(scenario: AccelGpsScenario, filter_model: LinearGaussianModel) -> np.ndarray:
    """The filter's transition of each interval with a scale-factor state, (K, 4, 4).

    The filter's own Phi^m (its bias decay, from the filter's settings) with the scale column of the
    acceleration profile, the one thing the filter shares with the truth: it depends on no truth setting
    but ``accel_amplitude`` and ``accel_frequency``.
    """
    s = scenario.scenario
    phi_m, _ = interval_transition(filter_model.phi, filter_model.gamma, filter_model.w, s.steps_per_update)
    return accel_gps_transitions(scenario, np.broadcast_to(phi_m, (s.n_updates, *phi_m.shape)))


def accel_gps_problem(
    scenario: AccelGpsScenario, form: UpdateForm = "joseph", residual_pairs: bool = True
) -> FixedGainProblem:
    """The report's filter against its truth, with the exact and the per-sample (sampled) engines.

    The truth's log-only GNSS faults (``truth.gps_latency``, ``gps_outlier_*``) are not in it: a
    verification and an analysis refuse them first (:func:`refuse_log_faults`).
    """
    s = scenario.scenario
    info = ProblemInfo(
        scenario=scenario.NAME,
        update_times=s.update_times(),
        state_names=scenario.state_names,
        state_units=scenario.state_units,
        measurement_names=MEASUREMENT_NAMES,
        measurement_units=MEASUREMENT_UNITS,
    )
    truth = accel_gps_truth(scenario)
    filter_model = scenario.filter_model()
    return FixedGainProblem(
        info=info,
        filter_model=filter_model,
        truth=truth,
        filter_transitions=accel_gps_filter_transitions(scenario, filter_model) if scenario.has_scale else None,
        sampled=partial(sample_accel_gps_errors, scenario),
        sampled_normals=sampled_normals_per_realization(scenario),
        sampled_block=partial(_sampled_block, scenario),
        form=form,
        residual_pairs=residual_pairs,
    )


def refuse_log_faults(scenario: AccelGpsScenario) -> None:
    """Raise a one-line SettingError naming the first log-only GNSS fault set in ``scenario.truth``.

    ``kalcal simulate`` writes them into logs; the exact truth has no time stamps to shift and no
    heavy-tailed fix noise, so a verification or analysis of them would verify something else.
    """
    t = scenario.truth
    for key in ("gps_latency", "gps_outlier_rate"):
        value = getattr(t, key)
        if value != 0 and (key == "gps_latency" or t.gps_outlier_std > 0):
            raise SettingError(
                f"truth.{key}",
                "0 in a verification (a log-only setting of kalcal simulate: the Monte Carlo's truth has no "
                "time stamps or gross fix errors)",
                show(value),
            )


def accel_gps_model_error_cause(scenario: AccelGpsScenario) -> str:
    """A sentence naming what makes the truth depart from the filter's model, for check details."""
    s = scenario.scenario
    causes = []
    if s.truth == "analytic":
        lag = " (the rectangle rule lags a(t) by half a sample)" if s.integration == "euler" else ""
        causes.append(f"the {s.integration} integration of the accelerometer against the analytic truth{lag}")
    f, t = scenario.filter_settings, scenario.truth
    if (f.position0_mean, f.velocity0_mean) != (t.position0_mean, t.velocity0_mean):
        causes.append("the filter's prior mean differing from the truth's")
    return " and ".join(causes)


def custom_problem(
    scenario: CustomModelScenario, form: UpdateForm = "joseph", residual_pairs: bool = True
) -> FixedGainProblem:
    """A model file's filter against its truth, sampled exactly at the update rate (no per-sample engine)."""
    m = scenario.model
    info = ProblemInfo(
        scenario=m.name,
        update_times=scenario.update_times,
        state_names=m.state_names,
        state_units=m.state_units,
        measurement_names=m.measurement_names,
        measurement_units=m.measurement_units,
    )
    try:
        return FixedGainProblem(
            info=info,
            filter_model=scenario.filter,
            truth=truth_from_model(scenario.truth, m.updates),
            form=form,
            residual_pairs=residual_pairs,
        )
    except np.linalg.LinAlgError:
        # NEES needs P_k^{-1}: a state that neither the prior, the process noise nor the fixes make uncertain
        raise ConfigError(
            f"{m.file}: the filter's covariance P_k is singular at some update (give the unobserved states "
            "prior variance in m0 or process noise through gamma and w)"
        ) from None


def custom_model_error_cause(scenario: CustomModelScenario) -> str:
    """The matrices of a model file's truth that can move the filter's mean error (x0, phi, h), or, for a
    truth with states of its own, that model (when a prior mean is nonzero: else both means stay zero)."""
    if scenario.truth_map is not None:
        if not (np.any(scenario.truth.x0) or np.any(scenario.filter.x0)):
            return ""
        n, d = scenario.truth.state_dim, scenario.filter.state_dim
        return f"the truth's own {n}-state model (its x0, phi and h, mapped to the filter's {d} state{'s' if d != 1 else ''})"
    keys = [k for k in scenario.differing() if k in ("x0", "phi", "h")]
    return f"the truth's {' and '.join(keys)} differing from the filter's" if keys else ""


def build_problem(scenario, form: UpdateForm = "joseph", residual_pairs: bool = True) -> tuple[Problem, str]:
    """The verification problem of a built-in scenario and the sentence naming its model error.

    ``residual_pairs=False`` skips E[r_k r_j^T] over all pairs (and so the whiteness check), for long
    horizons where only the other statistics are wanted.
    """
    if isinstance(scenario, AccelGpsScenario):
        return accel_gps_problem(scenario, form, residual_pairs), accel_gps_model_error_cause(scenario)
    if isinstance(scenario, ScaleBiasScenario):
        # The scale/bias filter's update form is its own setting, filter.form ("joseph" or "note").
        if form != "joseph":
            raise ConfigError(f"--form: {form!r} is not available for scale-bias (set filter.form=joseph or note instead)")
        return ScaleBiasProblem(scenario, residual_pairs=residual_pairs), model_error_cause(scenario)
    if isinstance(scenario, CustomModelScenario):
        return custom_problem(scenario, form, residual_pairs), custom_model_error_cause(scenario)
    raise TypeError(f"no verification problem for {type(scenario).__name__}")


def _sampled_block(scenario, *args):
    """The sampled engine's compiled block (:func:`kalcal.scenarios.accel_gps.sampled_kernels.accel_gps_block_sums`),
    its numba module loaded when a run first calls it, not when a problem is built."""
    from kalcal.scenarios.accel_gps.sampled_kernels import accel_gps_block_sums

    return accel_gps_block_sums(scenario, *args)
