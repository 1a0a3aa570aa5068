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
    out: str | Path | None = None,
) -> SimulationResult:
    """Simulate one realization drawn with ``seed``.

    accel-gps: ``logs["imu"]`` (time [s], accel [m/s^2]), ``logs["gps"]`` (time [s], position [m],
    velocity [m/s]) and ``logs["truth"]`` (time, position, velocity, accel, bias at the samples);
    scale-bias: ``logs["data"]`` (time, reference, sensor) and ``truth`` (the drawn scale error, bias, ...).
    ``settings`` takes ``--set``'s keys; ``out`` also writes the files, as ``kalcal simulate --out``.
    """
    from kalcal.api._scenario import resolve

    model = resolve(scenario, settings, config)
    if out is None:
        return model.simulate(seed)
    from kalcal.io.outputs import inputs_of, run_outputs

    with run_outputs(out, f"simulate {model.NAME}", names=model.output_names("simulate"), protect=inputs_of(model)) as staging:
        simulation = model.simulate(seed)
        paths = simulation.save(staging)
    return simulation.with_paths({key: Path(out) / Path(path).relative_to(staging) for key, path in paths.items()})
