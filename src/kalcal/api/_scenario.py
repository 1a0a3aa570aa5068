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
    defaults: Mapping[str, Any] | None = None,
    models: bool = False,
    command: str | None = None,
):
    """The scenario object of ``scenario`` with ``settings`` (``{"section.key": value}``, ``--set``'s keys)
    and the TOML ``config`` applied (what the scenario cannot do, an engine or a long run, its capabilities
    refuse: :func:`kalcal.scenarios.protocol.require`). With ``models``, which every command's API passes (sweep
    for a model file), a model file, a :class:`~kalcal.api.model.Model` or a model written as code is taken
    (what one cannot do, its capabilities refuse); without it (sweep of any other) a name goes to the
    registry, which refuses any but a built-in that has ``command``."""
    from kalcal.scenarios import build_scenario, is_model_file, load_model_file, model_file_fields

    assignments = assignments_of(settings)
    if models and _is_code(scenario):
        from kalcal.scenarios import load_code_model

        return load_code_model(scenario, assignments, config)
    inputs: tuple[str, ...] = ()
    fields = model_file_fields(scenario) if models else None
    if fields is not None:
        # a built model (kalcal.load_model) goes the way of its file: --set's assignments, the same refusals
        from kalcal.io.outputs import inputs_of

        inputs, scenario = inputs_of(scenario), Model(**fields)
    is_model = isinstance(scenario, Model) or (isinstance(scenario, (str, Path)) and is_model_file(str(scenario)))
    if models and is_model:
        # its engines and whether it has a long run are its capabilities, refused by verify's check_arguments
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
        return build_scenario(str(scenario), config, assignments, defaults=defaults, command=command)
    if settings or config is not None:
        from kalcal.models.config import apply_settings, load_toml

        merged = {**(load_toml(config) if config is not None else {}), **flat_settings(settings)}
        return apply_settings(scenario, merged)
    return scenario  # a scenario built already (kalcal.load_model, build_scenario)



def _is_code(scenario: Any) -> bool:
    """A model written as code: a ``.py`` path, a NonlinearModel, or a (truth, filter) pair of them."""
    from kalcal.scenarios import is_code_model

    if is_code_model(scenario):
        return True
    from kalcal.core.nonlinear import NonlinearModel

    return isinstance(scenario, NonlinearModel) or (
        isinstance(scenario, tuple) and len(scenario) == 2 and all(isinstance(m, NonlinearModel) for m in scenario)
    )


def with_data(scenario: Any, data: str | Path | None, command: str, topic: str | None = None) -> Any:
    """The resolved ``scenario`` over the log ``data`` (``--data LOG``, ``--topic`` its bag's or ULog's
    topic) where one is given: a model file with a [data] table only (its ``over_log``,
    :mod:`kalcal.scenarios.model_file.over_log`), else refused in one line (the protocol's default,
    :meth:`kalcal.scenarios.protocol.ScenarioDefaults.over_log`)."""
    with_topic(scenario, {"data": data}, topic)
    if data is None:
        return scenario
    return scenario.over_log(data, command) if topic is None else scenario.over_log(data, command, topic=topic)


def with_topic(scenario: Any, logs: dict[str, Any], topic: str | None) -> dict[str, Any]:
    """``logs`` with ``topic`` (``--topic``: which topic of ``--data``'s ROS bag or ULog a model file's
    [data] table reads) under ``"topic"``; ``logs`` as they are without one.

    Raises
    ------
    KalcalError
        One line: a topic without ``--data``, or for a built-in scenario (which names a topic by its
        columns' ``TOPIC.FIELD`` names, or reads the only one a bag has).
    """
    if topic is None:
        return logs
    if logs.get("data") is None:
        raise KalcalError(f"--topic: {topic!r} names a topic of --data's ROS bag or ULog, and no --data is given")
    from kalcal.scenarios import model_file_fields

    if model_file_fields(scenario) is None:  # the registry says whether it is a model file, not its name
        raise KalcalError(
            f"--topic: read by a model file's [data] table only; {getattr(scenario, 'NAME', scenario)} names a "
            "topic by its columns (TOPIC.FIELD)"
        )
    return {**logs, "topic": topic}


def command_label(verb: str, scenario: Any) -> str:
    """The command an output folder records (and a clash with another command's folder names): ``verb`` and
    the built-in scenario's name, or for a model file or a model written as code its label, which names the
    file (``calibrate a model file (my-model.toml)``), not the internal name all model files share.

    Parameters
    ----------
    verb : str
        The command: ``calibrate``, ``fit`` or ``simulate``.
    scenario : Scenario
        The resolved scenario the command runs.

    Returns
    -------
    str
        ``"VERB NAME"`` for a built-in scenario, ``"VERB LABEL"`` for one read from a file.
    """
    from kalcal.scenarios import scenario_names

    # a built-in's label carries its settings (imu-3axis's poses): the folder is the name's, as before
    label = None if scenario.NAME in scenario_names() else getattr(scenario, "label", None)
    return f"{verb} {label or scenario.NAME}"
