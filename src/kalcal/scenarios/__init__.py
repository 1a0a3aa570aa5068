"""The scenarios, one package each, and the one registry of them: names, classes, construction.

Five kinds, each in its package, which holds everything that is its own: three built-ins by name,
accel-gps (:mod:`kalcal.scenarios.accel_gps`), scale-bias (:mod:`kalcal.scenarios.scale_bias`) and
imu-3axis (:mod:`kalcal.scenarios.imu_3axis`); a model file (:mod:`kalcal.scenarios.model_file`); and a
model written as code (:mod:`kalcal.scenarios.nonlinear`). The rest of kalcal asks a scenario
through the :class:`~kalcal.scenarios.protocol.Scenario` protocol, never by its name or class
(tests/scenarios/test_scenario_boundary.py walks every module for that). This module is the only way in:
the built-in names (:func:`scenario_names`, for ``--help`` without importing numpy: the classes load on
first use), the classes (``SCENARIOS``), a scenario built from defaults, a TOML file and overrides
(:func:`build_scenario`), a model file (:func:`is_model_file`, :func:`load_model_file`,
:func:`parse_model_file`, and back to its fields, :func:`model_file_fields`), and a model written as code
(:func:`is_code_model`, :func:`load_code_model`).
"""

from __future__ import annotations

import importlib
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, NamedTuple

# name -> (module, class) of each built-in scenario, imported on first use: --help lists the names
# without loading numpy, and a scenario's modules may import this registry without a cycle
_BUILT_IN: dict[str, tuple[str, str]] = {
    "accel-gps": ("kalcal.scenarios.accel_gps.settings", "AccelGpsScenario"),
    "scale-bias": ("kalcal.scenarios.scale_bias.settings", "ScaleBiasScenario"),
    "imu-3axis": ("kalcal.scenarios.imu_3axis.settings", "Imu3AxisScenario"),
}

MODEL_FILE = "model-file"
"""What a model file (a linear Gaussian model in TOML, docs/custom-models.md) is called where a scenario's name is asked."""

__all__ = [
    "MODEL_FILE", "SCENARIOS", "build_scenario", "is_code_model", "load_code_model", "is_model_file", "load_model_file", "model_file_fields", "parse_model_file",
    "calibrate_option_takers", "scenario_class", "scenario_names", "scenarios_with",
    "log_defaults", "NoiseFilter", "noise_filter", "scenario_of_summary", "settings_assignments",
]


def scenario_names() -> tuple[str, ...]:
    """The built-in scenarios' names, in the order ``--help`` lists them."""
    return tuple(_BUILT_IN)


def scenarios_with(command: str) -> tuple[str, ...]:
    """The built-in scenarios whose capabilities have ``command`` (for a refusal's list of what does)."""
    return tuple(name for name in _BUILT_IN if command in scenario_class(name).capabilities.commands)


def scenario_class(name: str) -> type:
    """The class of the built-in scenario ``name`` (KeyError for another name)."""
    module, cls = _BUILT_IN[name]
    return getattr(importlib.import_module(module), cls)


def __getattr__(name: str) -> Any:
    # SCENARIOS (name -> class) is built on first use, as its classes are
    if name == "SCENARIOS":
        return {key: scenario_class(key) for key in _BUILT_IN}
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def calibrate_option_takers(option: str) -> list[str]:
    """The scenarios whose ``calibrate`` takes ``option`` (a field of
    :class:`~kalcal.results.calibration.CalibrateOptions`), by each class's ``CALIBRATE_OPTIONS``: the
    built-ins by name, then "a model file"; for the refusal of an option a scenario does not take."""
    from kalcal.scenarios.model_file.model import CustomModelScenario

    takers = [name for name in _BUILT_IN if option in scenario_class(name).CALIBRATE_OPTIONS]
    return takers + (["a model file"] if option in CustomModelScenario.CALIBRATE_OPTIONS else [])


def is_model_file(scenario: str) -> bool:
    """Whether ``scenario`` names a model file rather than a built-in scenario."""
    from kalcal.scenarios.model_file.model import is_model_file as is_file

    return is_file(scenario)


def is_code_model(scenario: Any) -> bool:
    """Whether ``scenario`` names a model written as code (a path ending in ``.py``: docs/nonlinear.md)."""
    return isinstance(scenario, (str, Path)) and str(scenario).lower().endswith(".py")


def load_code_model(scenario: Any, assignments: Iterable[str] = (), config: str | Path | None = None):
    """The nonlinear scenario of a model written as code: a ``.py`` path, a :class:`kalcal.NonlinearModel`
    (truth and filter) or a ``(truth, filter)`` pair, with ``section.key=value`` assignments applied
    (``filter.kind``, ``scenario.updates``, ``checks.tolerance``, ...)."""
    from kalcal.core.nonlinear import NonlinearModel
    from kalcal.models.config import apply_settings, load_toml
    from kalcal.models.settings import parse_assignments
    from kalcal.scenarios.nonlinear.settings import NonlinearModelSection, NonlinearScenario, register_models

    if isinstance(scenario, NonlinearModel):
        file = register_models(scenario, scenario)
    elif isinstance(scenario, tuple) and len(scenario) == 2 and all(isinstance(m, NonlinearModel) for m in scenario):
        file = register_models(*scenario)
    else:
        file = str(scenario)
    built = NonlinearScenario(model=NonlinearModelSection(file))
    settings = dict(load_toml(config)) if config is not None else {}
    settings.update(parse_assignments(assignments))
    return apply_settings(built, settings) if settings else built


def load_model_file(*args, **kwargs):
    """The model-file scenario of a TOML file (:func:`kalcal.scenarios.model_file.model.load_model_file`)."""
    from kalcal.scenarios.model_file.model import load_model_file as load

    return load(*args, **kwargs)


def parse_model_file(text: str, source: str, assignments: Iterable[str] = ()):
    """The model-file scenario of a model file's text (:func:`kalcal.scenarios.model_file.model.parse_model`);
    ``source`` names the file in errors and outputs."""
    from kalcal.scenarios.model_file.model import parse_model

    return parse_model(text, source, assignments)


def model_file_fields(scenario: Any) -> dict[str, Any] | None:
    """The model file's fields of a built model-file scenario (the keyword arguments of :class:`kalcal.Model`,
    :func:`kalcal.scenarios.model_file.model.model_fields`); None for any other scenario or object."""
    from kalcal.scenarios.model_file.model import CustomModelScenario, model_fields

    return model_fields(scenario) if isinstance(scenario, CustomModelScenario) else None


def build_scenario(
    name: str,
    config: str | Path | None = None,
    assignments: Iterable[str] = (),
    defaults: Mapping[str, Any] | None = None,
    command: str | None = None,
):
    """The named scenario with ``defaults``, then the TOML file, then ``section.key=value`` applied.

    An unknown name is refused naming the built-ins that have ``command`` (every built-in without one).

    An error about a value the file set names the file; one about a ``--set`` value names its key alone.

    The config file is recorded on the scenario (:func:`kalcal.io.outputs.mark_inputs`): a job writing
    outputs with it never removes or replaces that file.
    """
    from kalcal.io.outputs import mark_inputs
    from kalcal.models.config import apply_settings, load_toml
    from kalcal.models.settings import SettingError, parse_assignments, show

    if name not in _BUILT_IN:
        # every command (sweep included) reads a .toml as a model file before any name reaches the registry
        hint = " (a model file, .toml, is given to a command as its SCENARIO, not looked up here)" if str(name).lower().endswith(".toml") else ""
        names = scenarios_with(command) if command else tuple(_BUILT_IN)
        raise SettingError("SCENARIO", f"one of {', '.join(names)}", f"{show(name)}{hint}")
    scenario = scenario_class(name)()
    settings: dict[str, Any] = dict(defaults or {})
    from_file = load_toml(config) if config is not None else {}
    settings.update(from_file)
    assigned = parse_assignments(assignments)
    settings.update(assigned)
    sources = {key: str(config) for key in from_file if key not in assigned}
    # a job given the scenario never removes or replaces the config it was read from
    files = {str(config): from_file} if config is not None else None  # the file's own, overridden ones too
    return mark_inputs(apply_settings(scenario, settings, sources, files), config)


def settings_assignments(settings: Mapping[str, Mapping[str, Any]]) -> list[str]:
    """``{"truth": {"bias_std": 0.1, "x": None}}`` -> ``["truth.bias_std=0.1"]`` (None: left at its default)."""
    return [
        f"{section}.{key}={value}"
        for section, values in settings.items()
        for key, value in values.items()
        if value is not None
    ]


def scenario_of_summary(name: str, settings: Mapping[str, Mapping[str, Any]]):
    """The scenario a run's ``summary.json`` was made with, from its ``scenario`` and ``settings``: a model
    file's from its matrices (its settings are sections model, filter and truth), a built-in's by its name
    with those settings assigned."""
    from kalcal.scenarios.model_file.model import CustomModelScenario, is_custom_settings

    from kalcal.scenarios.model_file.over_log import LoggedModelScenario, settings_have_log

    if settings_have_log(settings):  # a model file's run over a log: read again from its recorded path
        return LoggedModelScenario.from_settings(settings)
    if is_custom_settings(settings):  # a model file's run: its matrices are the settings
        return CustomModelScenario.from_settings(settings)
    if set(settings) == {"model", "filter", "scenario", "checks"} and is_code_model(settings["model"].get("file", "")) or (
        str(name).startswith("nonlinear (")
    ):  # a model written as code: its file and settings
        rest = {key: value for key, value in settings.items() if key != "model"}
        return load_code_model(settings["model"]["file"], settings_assignments(rest))
    return build_scenario(name, None, settings_assignments(settings))


def log_defaults(scenario: Any) -> dict[str, Any]:
    """The settings a command on logged data starts from for ``scenario`` (a built-in's name or a built
    scenario): its class's ``LOG_DEFAULTS`` (accel-gps: the trapezoid), {} for anything else."""
    cls = scenario_class(str(scenario)) if isinstance(scenario, (str, Path)) and str(scenario) in _BUILT_IN else type(scenario)
    return dict(getattr(cls, "LOG_DEFAULTS", {}))


#: the module of the scenario whose ``[filter]`` settings ``kalcal noise`` writes (an accelerometer's
#: densities: accel-gps's filter), with ``filter_settings``, ``per_sample_settings`` and ``filter_toml``
_NOISE_FILTER = "kalcal.scenarios.accel_gps.noise_settings"


class NoiseFilter(NamedTuple):
    """What ``kalcal noise`` writes of one identified accelerometer noise: a scenario's ``[filter]``."""

    settings: dict[str, float]  #: summary.json's ``filter``: the densities written, by key
    per_sample: dict[str, Any]  #: summary.json's ``per_sample``: their per-sample values at the log's rate
    toml: str  #: filter.toml's text, for ``kalcal calibrate accel-gps --config``


def noise_filter(result: Any, source: str) -> NoiseFilter:
    """The ``[filter]`` settings of the accelerometer noise identified in ``result``
    (:class:`~kalcal.calibration.noise.NoiseIdentification`), read from ``source`` (what filter.toml's
    header names: the log, and the axis of a 3-axis one), as values and text."""
    module = importlib.import_module(_NOISE_FILTER)
    settings = module.filter_settings(result)
    return NoiseFilter(settings, module.per_sample_settings(result, settings), module.filter_toml(result, settings, source))
