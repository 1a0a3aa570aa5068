"""``kalcal.simulate``: one realization as the logs a user would record, returned as DataFrames."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from kalcal.results.simulation import SimulationResult


def simulate(
    scenario: str = "accel-gps",
    seed: int = 0,
    settings: Mapping[str, Any] | None = None,
    *,
    config: str | Path | None = None,
    data=None,
    out: str | Path | None = None,
    topic: str | None = None,
) -> SimulationResult:
    """Simulate one realization drawn with ``seed``.

    accel-gps: ``logs["imu"]`` (time [s], accel [m/s^2]), ``logs["gps"]`` (time [s], position [m],
    velocity [m/s]) and ``logs["truth"]`` (time, position, velocity, accel, bias at the samples);
    scale-bias: ``logs["data"]`` (time, reference, sensor) and ``truth`` (the drawn scale error, bias, ...).
    A model file (``MODEL.toml``, a :class:`kalcal.Model`) with a ``[data]`` table: ``logs["data"]``, a log in
    the file's layout over the rows of ``data`` (a path or DataFrame: its times, inputs, data columns and
    stds kept, the measurements drawn where it has them, the true states as ``<state>_true``) and ``truth``
    (truth.json; :mod:`kalcal.scenarios.model_file.simulate`); the built-ins refuse a ``data``.
    ``settings`` takes ``--set``'s keys; ``out`` also writes the files, as ``kalcal simulate --out``;
    ``topic`` (a model file's ``data`` that is a ROS bag or ULog) the topic its [data] table reads.
    """
    from kalcal.api._scenario import resolve

    model = resolve(scenario, settings, config, models=True)
    from kalcal.scenarios.protocol import require

    require(model, "simulate")  # a command the scenario lacks: one line naming it and why
    from kalcal.api._scenario import with_topic

    logs = with_topic(model, {"data": data}, topic)
    if out is None:
        return model.simulate(seed, logs)
    from kalcal.api._scenario import command_label
    from kalcal.io.outputs import inputs_of, run_outputs

    names = model.output_names("simulate")
    protect = [*([data] if isinstance(data, (str, Path)) else []), *inputs_of(model)]
    with run_outputs(out, command_label("simulate", model), names=names, protect=protect) as staging:
        simulation = model.simulate(seed, logs)
        paths = simulation.save(staging)
    return simulation.with_paths({key: Path(out) / Path(path).relative_to(staging) for key, path in paths.items()})
