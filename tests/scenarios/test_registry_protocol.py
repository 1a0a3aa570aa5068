"""Every scenario kalcal can build answers the Scenario protocol: the registry's built-in classes, a model
file's scenario with and without a [data] table, a model file over a log (``--data LOG``), a nonlinear model
written as code and imu-3axis; for every command each either answers (its files) or refuses in one line;
and each protocol method takes the Protocol's arguments (a wrong arity fails here, not in a user's run)."""

import dataclasses
import inspect
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from kalcal.errors import KalcalError
from kalcal.scenarios import SCENARIOS, load_code_model, load_model_file, parse_model_file
from kalcal.scenarios.protocol import COMMANDS, Capabilities, Scenario

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
#: the example model files (examples/ also holds settings files, which are not scenarios): three without a
#: [data] table, two with one
MODEL_FILES = ("constant_velocity.toml", "constant_velocity_mistuned.toml", "accel_gps_colored_gps.toml",
               "accel_gps_seed000.toml", "scale_bias_seed003.toml")
#: a model file whose row of h is read from a log's column ``c``: verified over a log only
LOGGED = """
name = "cv-logged"
sample_period = 0.1
steps_per_update = 10
updates = 30
phi   = [[1.0, 0.1], [0.0, 1.0]]
gamma = [[0.005], [0.1]]
h     = [["c", 0.0]]
w     = [[0.04]]
v     = [[4.0]]
x0    = [0.0, 10.0]
m0    = [[25.0, 0.0], [0.0, 1.0]]
[data]
measurements = ["z"]
"""
#: what each kind is built from, by id; built in the test (the log over which a model file runs is a file)
KINDS = (*SCENARIOS, *MODEL_FILES, "model-file-over-log", "range_bearing.py")


def _logged(tmp_path: Path):
    z = np.full(301, np.nan)
    z[10::10] = 0.0  # which rows are measured; the values are not read by verify
    log = tmp_path / "log.csv"
    pd.DataFrame({"z": z, "c": np.ones(301)}).to_csv(log, index=False)
    return parse_model_file(LOGGED, "cv-logged.toml").over_log(str(log), "verify")


def _build(kind: str, tmp_path: Path):
    if kind in SCENARIOS:
        return SCENARIOS[kind]()
    if kind == "model-file-over-log":
        return _logged(tmp_path)
    if kind.endswith(".py"):
        return load_code_model(EXAMPLES / kind)
    return load_model_file(EXAMPLES / kind)


def _one_line_refusal(call) -> str:
    with pytest.raises(KalcalError) as raised:
        call()
    message = str(raised.value)
    assert message and "\n" not in message, message
    return message


#: the protocol's methods (the properties and class constants aside), each checked for its parameters
METHODS = tuple(
    name for name, member in vars(Scenario).items()
    if inspect.isfunction(member) and not name.startswith("_")
)


def _parameters(function) -> list[tuple[str, object, bool]]:
    """(name, kind, has a default) of each parameter: what a caller relies on (annotations aside)."""
    return [(p.name, p.kind, p.default is not inspect.Parameter.empty) for p in inspect.signature(function).parameters.values()]


@pytest.mark.parametrize("kind", KINDS)
def test_each_scenario_answers_the_protocol(kind, tmp_path):
    scenario = _build(kind, tmp_path)
    assert isinstance(scenario, Scenario), kind
    caps = scenario.capabilities
    assert isinstance(caps, Capabilities)
    assert caps.exact_analysis == bool(scenario.error_sources())
    assert isinstance(scenario.NAME, str) and scenario.NAME
    for name in METHODS:  # the arity the rest of kalcal calls it with
        assert _parameters(getattr(type(scenario), name)) == _parameters(getattr(Scenario, name)), (kind, name)
    for command in sorted(COMMANDS):
        if command in caps.commands:
            names = scenario.output_names(command)
            assert isinstance(names, tuple) and all(isinstance(n, str) and n for n in names), (kind, command)
            if command in ("simulate", "calibrate", "fit"):
                assert names, (kind, command)  # a command that writes files names them
            continue
        from kalcal.scenarios.protocol import require

        message = _one_line_refusal(lambda: require(scenario, command))
        assert (getattr(scenario, "label", None) or scenario.NAME) in message
        if command in ("simulate", "calibrate", "fit"):
            # asked directly, the scenario refuses in the same line: output_names and the method itself
            assert _one_line_refusal(lambda: scenario.output_names(command)) == message
            call = {"simulate": lambda: scenario.simulate(0, None), "calibrate": lambda: scenario.calibrate({}, None),
                    "fit": lambda: scenario.fit({}, None)}[command]
            assert _one_line_refusal(call) == message, (kind, command)
    assert isinstance(scenario.source_report(), bool)
    pair = scenario.residual_pair_times()  # the report's pair of times, for its setup alone
    assert pair is None if not scenario.source_report() else (len(pair) == 2 and all(isinstance(t, float) for t in pair))
    k, t_k = scenario.run_length()
    assert isinstance(k, int) and k >= 0 and t_k >= 0
    for section in dataclasses.fields(scenario):  # what apply_settings changes: the section as given
        if section.init:
            assert type(scenario.given_section(section.name)) is type(getattr(scenario, section.name))
    labels = scenario.state_labels  # one per filter state, or None: the problem's names say it
    if "verify" not in caps.commands:  # no Monte Carlo, no problem to name states
        return
    problem = scenario.problem(residual_pairs=False)
    assert set(caps.engines) <= set(problem.engines), (kind, caps.engines, problem.engines)  # one set of engine names
    d = len(problem.info.state_names)
    assert labels is None or (len(labels) == d and all(isinstance(label, str) and label for label in labels))


def test_every_kind_of_scenario_is_covered(tmp_path):
    """The parametrized test reaches every class of scenario kalcal builds, not only the registry's: a model
    file with and without [data], one over a log, a model written as code."""
    built = [_build(kind, tmp_path) for kind in KINDS]
    classes = {type(s).__name__ for s in built}
    assert {"AccelGpsScenario", "ScaleBiasScenario", "Imu3AxisScenario", "CustomModelScenario",
            "LoggedModelScenario", "NonlinearScenario"} <= classes
    files = [s for s in built if type(s).__name__ == "CustomModelScenario"]
    assert any(s.data is None for s in files) and any(s.data is not None for s in files)


@pytest.mark.parametrize("call, scenario", [
    ("simulate", "imu-3axis"), ("fit", "imu-3axis"), ("simulate", "range_bearing.py"), ("calibrate", "range_bearing.py"),
    ("fit", "range_bearing.py"), ("simulate", "constant_velocity.toml"), ("calibrate", "constant_velocity.toml"),
])
def test_the_api_refuses_a_command_the_scenario_lacks_in_one_line(call, scenario):
    """kalcal.simulate / calibrate / fit ask the scenario's capabilities first: one line naming it and why,
    not a TypeError or KeyError from inside."""
    import kalcal

    target = scenario if scenario in SCENARIOS else str(EXAMPLES / scenario)
    message = _one_line_refusal(lambda: getattr(kalcal, call)(target))
    assert ("imu-3axis" if scenario == "imu-3axis" else scenario) in message


@pytest.mark.parametrize("args", [["simulate", "imu-3axis"], ["fit", "imu-3axis", "--data", "x.csv"]])
def test_the_cli_refuses_a_command_the_scenario_lacks_with_status_2(args):
    from kalcal.cli import app

    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output and "imu-3axis" in result.output


def test_the_noise_filter_is_values_and_text_from_the_registry():
    """kalcal noise asks the registry for the [filter] it writes and gets values and text, not a scenario's
    module: the densities, their per-sample values at the log's rate, filter.toml naming its source."""
    import numpy as np

    from kalcal.calibration.noise import identify_noise
    from kalcal.scenarios import NoiseFilter, noise_filter

    rate = 100.0
    result = identify_noise(np.random.default_rng(0).normal(0.05, 0.02, 20_000), rate)
    written = noise_filter(result, "imu.csv")
    assert isinstance(written, NoiseFilter)
    assert written.settings["accel_noise_density"] > 0
    # per sample at the log's rate: accel_noise_std = N sqrt(rate)
    assert written.per_sample["rate"] == rate
    assert written.per_sample["accel_noise_std"] == pytest.approx(written.settings["accel_noise_density"] * np.sqrt(rate), rel=1e-12)
    assert "imu.csv" in written.toml and "[filter]" in written.toml


def test_a_calibrate_option_is_refused_naming_the_scenarios_that_take_it(monkeypatch):
    """Who takes an option is each class's CALIBRATE_OPTIONS, asked of the registry, not a name written in
    shared code: a made-up taker of --poses appears in the refusal."""
    from kalcal.results.calibration import CalibrateOptions
    from kalcal.scenarios import calibrate_option_takers, scenario_class

    assert calibrate_option_takers("poses") == ["imu-3axis"]
    assert calibrate_option_takers("smooth") == ["accel-gps", "a model file"]
    options = CalibrateOptions(poses="poses.json")
    message = _one_line_refusal(lambda: options.refuse_unless("accel-gps", scenario_class("accel-gps").CALIBRATE_OPTIONS))
    assert message == "--poses: not available for accel-gps (imu-3axis only)"
    cls = scenario_class("scale-bias")
    monkeypatch.setattr(cls, "CALIBRATE_OPTIONS", (*cls.CALIBRATE_OPTIONS, "poses"))
    message = _one_line_refusal(lambda: options.refuse_unless("accel-gps", scenario_class("accel-gps").CALIBRATE_OPTIONS))
    assert message == "--poses: not available for accel-gps (scale-bias and imu-3axis only)"


def test_an_unknown_scenario_of_sweep_lists_those_that_have_a_sweep():
    import kalcal
    from kalcal.scenarios import scenarios_with

    assert "imu-3axis" not in scenarios_with("sweep") and "accel-gps" in scenarios_with("sweep")
    message = _one_line_refusal(lambda: kalcal.sweep("X.py", "filter.x", [1, 2], out="unused"))
    assert f"one of {', '.join(scenarios_with('sweep'))}," in message and "imu-3axis" not in message
