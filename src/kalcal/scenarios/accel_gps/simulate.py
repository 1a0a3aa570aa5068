"""``kalcal simulate accel-gps``: one realization as the accelerometer and GPS logs a user would record."""

from __future__ import annotations

import numpy as np

from kalcal.results.simulation import SimulationResult
from kalcal.scenarios.accel_gps.sampled import sample_accel_gps_logs

#: the files of an accel-gps simulation
OUTPUT_NAMES = ("imu.csv", "gps.csv", "truth.csv")


def compute_accel_gps_simulation(scenario, seed: int) -> SimulationResult:
    """imu: time [s], accel [m/s^2], one row per accelerometer sample from t = 0.
    gps: time [s], position [m], velocity [m/s], one row per fix; time is the stamp, the time the fix
    describes plus ``truth.gps_latency``, and ``truth.gps_outlier_rate`` of the positions carry a gross error.
    truth: time [s], position [m], velocity [m/s], accel [m/s^2] (true), bias [m/s^2] at the samples."""
    import pandas as pd

    logs = sample_accel_gps_logs(scenario, np.random.default_rng(seed), 1)
    return SimulationResult(
        scenario.NAME,
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
        None,
        OUTPUT_NAMES,
    )
