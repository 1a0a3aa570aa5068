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
from kalcal.montecarlo.problem import FixedGainProblem, ProblemInfo
from kalcal.simulate.exact import accel_gps_truth
from kalcal.simulate.sampled import sample_accel_gps_errors


def accel_gps_problem(scenario: AccelGpsScenario, form: UpdateForm = "joseph") -> FixedGainProblem:
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
    )
