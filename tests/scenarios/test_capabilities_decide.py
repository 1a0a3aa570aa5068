"""The scenario's capabilities, not the problem's class, decide what the checks, the power and the report do."""

from __future__ import annotations

import dataclasses

import pytest

from kalcal.api.verification import check_arguments
from kalcal.errors import ConfigError
from kalcal.montecarlo.scenarios import build_problem
from kalcal.reporting.steady_state import steady_state_view
from kalcal.scenarios import build_scenario
from kalcal.stats.self_check import exact_prediction
from kalcal.stats.suite import problem_power


def _without(problem, **changes):
    info = dataclasses.replace(problem.info, capabilities=dataclasses.replace(problem.info.capabilities, **changes))
    object.__setattr__(problem, "info", info)
    return problem


def test_a_fixed_gain_problem_whose_scenario_declares_no_exact_analysis_gets_none():
    problem = build_problem(build_scenario("accel-gps"))[0]
    assert exact_prediction(problem).available and problem_power(problem, 1000, 0.99)[0] is not None
    _without(problem, exact_analysis=False, fixed_gains=False)
    assert not exact_prediction(problem).available
    assert problem_power(problem, 1000, 0.99)[0] is None
    view = steady_state_view(problem)
    assert not view.applies and view.reason  # no fixed gains: no steady state, with a reason


def test_an_engine_and_a_long_run_are_refused_by_the_scenarios_capabilities():
    scenario = build_scenario("scale-bias")
    with pytest.raises(ConfigError, match=r"^--engine: 'sampled' is not available for scale-bias; use exact$"):
        check_arguments(scenario, 200, engine="sampled")
    check_arguments(build_scenario("accel-gps"), 200, engine="sampled")  # declared: passes
