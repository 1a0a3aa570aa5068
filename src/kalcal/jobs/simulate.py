"""``kalcal simulate``: write one simulated realization as a user would record it."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from kalcal.io.outputs import writes_outputs
from kalcal.io.results import write_csv
from kalcal.models.accel_gps import AccelGpsScenario
from kalcal.simulate.sampled import sample_accel_gps_logs


@writes_outputs("simulate accel-gps", names=("imu.csv", "gps.csv", "truth.csv"))
def simulate_accel_gps(scenario: AccelGpsScenario, seed: int, out: str | Path) -> dict[str, Path]:
    """Write ``imu.csv``, ``gps.csv`` and ``truth.csv`` for one realization drawn with ``seed``.

    imu.csv: time [s], accel [m/s^2], one row per accelerometer sample from t = 0.
    gps.csv: time [s], position [m], velocity [m/s], one row per fix.
    truth.csv: time [s], position [m], velocity [m/s], accel [m/s^2] (true), bias [m/s^2] at the samples.
    """
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(seed), 1)
    out = Path(out)
    return {
        "imu": write_csv(out / "imu.csv", {"time": logs.sample_time, "accel": logs.accel[0]}),
        "gps": write_csv(
            out / "gps.csv",
            {"time": logs.fix_time, "position": logs.gps_position[0], "velocity": logs.gps_velocity[0]},
        ),
        "truth": write_csv(
            out / "truth.csv",
            {
                "time": logs.sample_time,
                "position": logs.position[0],
                "velocity": logs.velocity[0],
                "accel": logs.true_accel,
                "bias": logs.bias[0],
            },
        ),
    }
