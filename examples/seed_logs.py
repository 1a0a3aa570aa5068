"""Write a built-in scenario's simulated logs in the [data] layout of its seed's model file.

    kalcal simulate accel-gps --seed 0 --out sim000
    python examples/seed_logs.py accel-gps sim000 seed000.csv     # for examples/accel_gps_seed000.toml
    kalcal simulate scale-bias --seed 3 --out sim003
    python examples/seed_logs.py scale-bias sim003 seed003.csv    # for examples/scale_bias_seed003.toml

accel-gps writes two logs (imu.csv: time, accel at 200 Hz; gps.csv: time, position, velocity at 5 Hz);
the model file reads one table with a row per accelerometer sample: time, accel, and position and
velocity on the rows of the samples the fixes fall on, NaN (an empty cell) between (with per-fix
position_std and velocity_std columns carried the same way where gps.csv has them). A fix must lie on a
sample (within ``ON_SAMPLE`` of a sample period): a model file steps once per row, so a fix between two
samples, which the built-in filter reaches by a partial step, has no row; it is refused, naming its row.
scale-bias's data.csv (time, reference, sensor, one row per sample) is already the file's layout.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd

#: how far (a fraction of the median sample step) a fix's time may lie from its sample's: rounding of
#: the times as written to CSV, far below any real offset between a GNSS stamp and an IMU sample
ON_SAMPLE = 1e-6


def accel_gps_table(imu: pd.DataFrame, gps: pd.DataFrame, source: str = "gps") -> pd.DataFrame:
    """One table with a row per accelerometer sample and each fix on its sample's row.

    Parameters
    ----------
    imu : DataFrame
        ``time`` (s, increasing) and ``accel`` (m/s^2), one row per sample, (J + 1) rows.
    gps : DataFrame
        ``time`` (s), ``position`` (m), ``velocity`` (m/s), optionally ``position_std`` (m) and
        ``velocity_std`` (m/s), one row per fix.
    source : str
        The GPS log's name in errors.

    Returns
    -------
    DataFrame
        ``time``, ``accel``, ``position``, ``velocity`` (and the std columns gps has), (J + 1) rows; the
        fix columns NaN on the rows without a fix.

    Raises
    ------
    ValueError
        One line naming the GPS log's row (1-based, as the built-in's messages count): a fix outside the
        accelerometer log, off every sample by more than ``ON_SAMPLE`` sample periods, or on the same
        sample as another fix.
    """
    time = imu["time"].to_numpy(dtype=float)
    fix_time = gps["time"].to_numpy(dtype=float)
    period = float(np.median(np.diff(time)))
    row = np.clip(np.searchsorted(time, fix_time), 1, time.size - 1)
    row = np.where(np.abs(time[row - 1] - fix_time) <= np.abs(time[row] - fix_time), row - 1, row)
    off = np.abs(time[row] - fix_time)
    outside = (fix_time < time[0] - ON_SAMPLE * period) | (fix_time > time[-1] + ON_SAMPLE * period)
    bad = outside | (off > ON_SAMPLE * period)
    if np.any(bad):
        k = int(np.argmax(bad))
        where = "outside the accelerometer log" if outside[k] else (
            f"{off[k]:.6g} s from the nearest sample (t = {time[row[k]]:.9g} s), more than {ON_SAMPLE:g} sample periods"
        )
        raise ValueError(f"{source}: row {k + 1}: fix at t = {fix_time[k]:.9g} s lies {where}: a model file steps once "
                         "per sample, so a fix needs a sample's row")
    twice = np.flatnonzero(np.diff(row) == 0)
    if twice.size:
        k = int(twice[0]) + 1
        raise ValueError(f"{source}: row {k + 1}: fix at t = {fix_time[k]:.9g} s falls on the sample of the fix before it")
    table = pd.DataFrame({"time": time, "accel": imu["accel"].to_numpy(dtype=float)})
    for column in ("position", "velocity", "position_std", "velocity_std"):
        if column in gps.columns:
            values = np.full(time.size, np.nan)
            values[row] = gps[column].to_numpy(dtype=float)
            table[column] = values
    return table


def scale_bias_table(data: pd.DataFrame) -> pd.DataFrame:
    """scale-bias's log as it is: ``time`` (s), ``reference`` and ``sensor`` (signal unit), a row per sample."""
    missing = [c for c in ("time", "reference", "sensor") if c not in data.columns]
    if missing:
        raise ValueError(f"data: missing column(s) {', '.join(missing)} (columns: {', '.join(map(str, data.columns))})")
    return data[["time", "reference", "sensor"]].copy()


def main(argv: list[str]) -> int:
    """``python examples/seed_logs.py accel-gps|scale-bias SIMULATION_DIR OUT.csv``; exit 2 on bad input."""
    if len(argv) != 3 or argv[0] not in ("accel-gps", "scale-bias"):
        print("usage: seed_logs.py accel-gps|scale-bias SIMULATION_DIR OUT.csv", file=sys.stderr)
        return 2
    scenario, folder, out = argv[0], Path(argv[1]), Path(argv[2])
    try:
        if scenario == "accel-gps":
            table = accel_gps_table(pd.read_csv(folder / "imu.csv"), pd.read_csv(folder / "gps.csv"), str(folder / "gps.csv"))
        else:
            table = scale_bias_table(pd.read_csv(folder / "data.csv"))
    except (OSError, ValueError, KeyError) as exc:
        print(f"seed_logs.py: error: {exc}", file=sys.stderr)
        return 2
    table.to_csv(out, index=False, float_format="%.17g")  # every digit: the log reads back bit for bit
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
