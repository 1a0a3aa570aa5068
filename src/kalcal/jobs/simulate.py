"""``kalcal simulate``: one simulated realization as a user would record it, drawn in memory, then written."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from kalcal.io.outputs import writes_outputs
from kalcal.io.results import write_json
from kalcal.scenarios.accel_gps.settings import AccelGpsScenario
from kalcal.scenarios.accel_gps.sampled import sample_accel_gps_logs

if TYPE_CHECKING:  # loaded where a simulation is made: a scale-bias calibration imports this module
    import pandas as pd

#: the files of a simulation of each scenario
OUTPUT_NAMES = {
    "simulate accel-gps": ("imu.csv", "gps.csv", "truth.csv"),
    "simulate scale-bias": ("data.csv", "truth.json"),
}


@dataclass(frozen=True)
class Simulation:
    """A simulated realization in memory: ``logs`` (name -> DataFrame, each written as ``NAME.csv``) and
    ``documents`` (name -> dict, each written as ``NAME.json``), for the command ``command``."""

    command: str
    logs: dict[str, pd.DataFrame]
    documents: dict[str, dict[str, Any]] = field(default_factory=dict)


def compute_simulation(scenario, seed: int) -> Simulation:
    """The realization of ``scenario`` drawn with ``seed`` (accel-gps or scale-bias)."""
    return scenario.simulate(seed)  # kalcal.scenarios.protocol.Scenario.simulate


def compute_accel_gps_simulation(scenario: AccelGpsScenario, seed: int) -> Simulation:
    """imu: time [s], accel [m/s^2], one row per accelerometer sample from t = 0.
    gps: time [s], position [m], velocity [m/s], one row per fix; time is the stamp, the time the fix
    describes plus ``truth.gps_latency``, and ``truth.gps_outlier_rate`` of the positions carry a gross error.
    truth: time [s], position [m], velocity [m/s], accel [m/s^2] (true), bias [m/s^2] at the samples."""
    import pandas as pd

    logs = sample_accel_gps_logs(scenario, np.random.default_rng(seed), 1)
    return Simulation(
        "simulate accel-gps",
        {
            "imu": pd.DataFrame({"time": logs.sample_time, "accel": logs.accel[0]}),
            "gps": pd.DataFrame(
                {"time": logs.fix_stamp, "position": logs.gps_position[0], "velocity": logs.gps_velocity[0]}
            ),
            "truth": pd.DataFrame(
                {
                    "time": logs.sample_time,
                    "position": logs.position[0],
                    "velocity": logs.velocity[0],
                    "accel": logs.true_accel,
                    "bias": logs.bias[0],
                }
            ),
        },
    )


def save_simulation(simulation: Simulation, out: str | Path) -> dict[str, Path]:
    """Write the logs as CSV and the documents as JSON into ``out`` as one set; returns the files by name."""

    @writes_outputs(simulation.command, names=OUTPUT_NAMES[simulation.command])
    def write(simulation: Simulation, out: Path) -> dict[str, Path]:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        paths: dict[str, Path] = {}
        for name, frame in simulation.logs.items():
            paths[name] = out / f"{name}.csv"
            frame.to_csv(paths[name], index=False)
        for name, document in simulation.documents.items():
            paths[name] = write_json(out / f"{name}.json", document)
        return paths

    return write(simulation, out)

