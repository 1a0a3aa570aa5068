"""The scenario of an API call: a built-in name, a model file, a :class:`~kalcal.api.model.Model` or a built scenario."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from kalcal.api.model import Model, assignments_of, flat_settings
from kalcal.errors import KalcalError


def resolve(
    scenario: Any,
    settings: Mapping[str, Any] | None,
    config: str | Path | None,
    *,
    engine: str = "exact",
    long_run: float | None = None,
    defaults: Mapping[str, Any] | None = None,
    models: bool = False,
):
    """The scenario object of ``scenario`` with ``settings`` (``{"section.key": value}``, ``--set``'s keys)
    and the TOML ``config`` applied; a model (file or :class:`Model`) refuses the sampled engine and a
    long run as ``kalcal verify`` does. Only with ``models`` (verify) is a model file or Model taken; elsewhere
    a name goes to the registry, which says that model files work with verify."""
    from kalcal.scenarios.model_file.model import is_model_file, load_model_file
    from kalcal.scenarios import build_scenario

    from kalcal.scenarios.model_file.model import CustomModelScenario

    assignments = assignments_of(settings)
    inputs: tuple[str, ...] = ()
    if isinstance(scenario, CustomModelScenario) and models:
        # a built model (kalcal.load_model) goes the way of its file: --set's assignments, the same refusals
        from kalcal.io.outputs import inputs_of

        inputs, scenario = inputs_of(scenario), model_of(scenario)
    is_model = isinstance(scenario, Model) or (isinstance(scenario, (str, Path)) and is_model_file(str(scenario)))
    if models and is_model:
        where = scenario.source if isinstance(scenario, Model) else str(scenario)
        if engine == "sampled":
            raise KalcalError(f"--engine: 'sampled' is not available for a model file ({where}); use the exact engine")
        if long_run:
            raise KalcalError(f"--long-run: not available for a model file ({where}); set updates in the file instead")
        if isinstance(scenario, Model):
            if config is not None:
                raise KalcalError("config: not used with a Model; give its settings to Model or settings=")
            built = scenario.scenario(settings)
            if inputs:
                from kalcal.io.outputs import mark_inputs

                mark_inputs(built, *inputs)  # the file it was read from stays protected
            return built
        return load_model_file(scenario, assignments, config=config)
    if isinstance(scenario, (str, Path)):
        return build_scenario(str(scenario), config, assignments, defaults=defaults)
    if settings or config is not None:
        from kalcal.models.config import apply_settings, load_toml

        merged = {**(load_toml(config) if config is not None else {}), **flat_settings(settings)}
        return apply_settings(scenario, merged)
    return scenario  # a scenario built already (kalcal.load_model, build_scenario)


def model_of(scenario) -> Model:
    """The :class:`Model` of a built custom scenario, its source the file it was read from."""
    f, t, info = scenario.filter, scenario.truth, scenario.model
    keys = ("phi", "gamma", "h", "w", "v", "x0", "m0")
    truth = {key: getattr(t, key).tolist() for key in scenario.differing()}
    return Model(
        **{key: getattr(f, key).tolist() for key in keys},
        steps_per_update=int(f.steps_per_update), updates=int(info.updates), sample_period=float(f.sample_period),
        truth=truth or None, name=info.name, state_names=list(info.state_names), state_units=list(info.state_units),
        measurement_names=list(info.measurement_names), measurement_units=list(info.measurement_units),
        source=info.file,
    )
