"""Verification problems for the built-in scenarios."""

from __future__ import annotations

from functools import partial

from kalcal.filters.kalman import UpdateForm
from kalcal.models.accel_gps import (
    MEASUREMENT_NAMES,
    MEASUREMENT_UNITS,
    STATE_NAMES,
    STATE_UNITS,
    AccelGpsScenario,
)
from kalcal.models.scale_bias import ScaleBiasScenario
from kalcal.montecarlo.problem import FixedGainProblem, ProblemInfo
from kalcal.montecarlo.scale_bias import ScaleBiasProblem, model_error_cause
from kalcal.simulate.exact import accel_gps_truth
from kalcal.simulate.sampled import sample_accel_gps_errors


def accel_gps_problem(
    scenario: AccelGpsScenario, form: UpdateForm = "joseph", residual_pairs: bool = True
) -> FixedGainProblem:
    """The report's filter against its truth, with the exact and the per-sample (sampled) engines."""
    s = scenario.scenario
    info = ProblemInfo(
        scenario=scenario.NAME,
        update_times=s.update_times(),
        state_names=STATE_NAMES,
        state_units=STATE_UNITS,
        measurement_names=MEASUREMENT_NAMES,
        measurement_units=MEASUREMENT_UNITS,
    )
    return FixedGainProblem(
        info=info,
        filter_model=scenario.filter_model(),
        truth=accel_gps_truth(scenario),
        sampled=partial(sample_accel_gps_errors, scenario),
        # p0, v0, b, the first sample; then m samples and 2 fix noises per interval
        sampled_normals=4 + s.n_updates * (s.steps_per_update + 2),
        form=form,
        residual_pairs=residual_pairs,
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


def build_problem(scenario, form: UpdateForm = "joseph", residual_pairs: bool = True) -> tuple[FixedGainProblem, str]:
    """The verification problem of a built-in scenario and the sentence naming its model error.

    ``residual_pairs=False`` skips E[r_k r_j^T] over all pairs (and so the whiteness check), for long
    horizons where only the other statistics are wanted.
    """
    if isinstance(scenario, AccelGpsScenario):
        return accel_gps_problem(scenario, form, residual_pairs), accel_gps_model_error_cause(scenario)
    if isinstance(scenario, ScaleBiasScenario):
        # The scale/bias filter's update form is its own setting, filter.form ("joseph" or "note").
        return ScaleBiasProblem(scenario, residual_pairs=residual_pairs), model_error_cause(scenario)
    raise TypeError(f"no verification problem for {type(scenario).__name__}")
