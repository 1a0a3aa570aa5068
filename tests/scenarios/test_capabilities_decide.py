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


def _problems(tmp_path):
    """A problem of every class kalcal builds: fixed gains, data-dependent gains, nonlinear (a model written
    as code, imu-3axis), a model file over a log."""
    import sys
    from pathlib import Path

    from kalcal.scenarios import load_code_model

    sys.path.insert(0, str(Path(__file__).parent))
    from test_registry_protocol import _logged

    example = Path(__file__).resolve().parents[2] / "examples" / "range_bearing.py"
    return {
        "accel-gps": build_problem(build_scenario("accel-gps"))[0],
        "scale-factor": build_problem(build_scenario("accel-gps", None, ["filter.scale_std=0.01"]))[0],
        "scale-bias": build_problem(build_scenario("scale-bias"))[0],
        "nonlinear": load_code_model(example).problem(residual_pairs=False),
        "imu-3axis": build_scenario("imu-3axis").problem(residual_pairs=False),
        "over-log": _logged(tmp_path).problem(),
    }


def test_every_problem_answers_the_problem_protocols_questions(tmp_path):
    """has_exact_analysis, steady_state_reason, effect_sizes and simulated_power are the protocol's, with
    defaults: each problem answers them, and the answers agree with its scenario's capabilities."""
    from kalcal.montecarlo.problem import VARYING_TRANSITION

    for name, problem in _problems(tmp_path).items():
        caps = problem.info.capabilities
        assert problem.has_exact_analysis() == caps.exact_analysis, name
        reason = problem.steady_state_reason()
        assert isinstance(reason, str) and (bool(reason) or caps.fixed_gains), name
        assert (problem.simulated_power(10, 0, 0.99) is None) or caps.nonlinear, name
    problems = _problems(tmp_path)
    assert problems["accel-gps"].steady_state_reason() == "" and problems["scale-factor"].steady_state_reason() == VARYING_TRANSITION
    assert "log" in problems["over-log"].steady_state_reason()
    assert "nonlinear" in problems["nonlinear"].steady_state_reason()


def test_the_nonlinear_capability_decides_whether_effect_sizes_are_kept():
    """A nonlinear model's run keeps its effect sizes; the same problem declared linear keeps none."""
    from pathlib import Path

    import numpy as np

    from kalcal.api.verification import problem_effects
    from kalcal.montecarlo.engine import run_monte_carlo
    from kalcal.scenarios import load_code_model

    example = Path(__file__).resolve().parents[2] / "examples" / "range_bearing.py"
    problem = load_code_model(example, ["scenario.updates=20"]).problem(residual_pairs=False)
    sums = run_monte_carlo(problem, 200, 0, engine="exact", workers=1).sums
    effects = problem_effects(problem, sums, 0.99)
    assert effects is not None and np.isfinite([e.value for e in effects.overall]).all()
    assert problem_effects(_without(problem, nonlinear=False), sums, 0.99) is None


def test_what_has_no_exact_analysis_says_why_from_its_capabilities(tmp_path):
    """The self-check's and the power's reason: rows from data say each realization has its own P; a
    nonlinear model says its P is a linearization's, not that its gains hold noisy readings."""
    problems = _problems(tmp_path)
    rows = exact_prediction(problems["scale-bias"]).reason
    assert "the measurement rows are data, so each realization has its own P" in rows
    nonlinear = exact_prediction(problems["nonlinear"]).reason
    assert "linearization" in nonlinear and "noisy readings" not in nonlinear
    assert "linearization" in problem_power(problems["imu-3axis"], 1000, 0.99)[1]
    assert exact_prediction(problems["accel-gps"]).available


def test_an_exact_analysis_of_a_problem_without_one_is_refused_by_the_protocol(tmp_path):
    from kalcal.analysis.fixed_gain import analyze_problem
    from kalcal.errors import KalcalError

    with pytest.raises(KalcalError, match="no exact covariance analysis"):
        analyze_problem(_problems(tmp_path)["scale-bias"])


def test_no_shared_module_probes_a_problem_for_what_the_protocol_answers():
    """getattr(problem, "effect_sizes" / "simulated_power" / "NOT_STEADY" / ...) outside the scenarios would
    decide behaviour by an attribute outside the protocol: none is left."""
    import ast
    from pathlib import Path

    import kalcal

    root = Path(kalcal.__file__).parent
    probed = {"effect_sizes", "simulated_power", "NOT_TIME_INVARIANT", "NOT_STEADY", "filter_transitions"}
    found = []
    for path in root.rglob("*.py"):
        if root / "scenarios" in path.parents:
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in ("getattr", "hasattr")
                    and len(node.args) >= 2 and isinstance(node.args[1], ast.Constant) and node.args[1].value in probed):
                found.append(f"{path.relative_to(root)}:{node.lineno}: {node.args[1].value}")
    assert not found, found
