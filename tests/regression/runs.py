"""Six small seeded verification runs whose statistics (all of ``stats.nc``) are held fixed.

The reference files in ``tests/regression/reference/`` are written by ``python -m tests.regression.runs``
(from the repository root) and compared by ``test_seeded_statistics.py``: a change that is meant to keep
the numbers (a refactor of the filter core, the moment sums, the engine) must keep them to rounding.
Rewrite the references only for a change that is meant to move the numbers, and name it in the commit.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import xarray as xr

REFERENCE = Path(__file__).parent / "reference"
EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
N = 1000
SEED = 11

#: name -> (scenario or model file, settings); short horizons keep the files small
RUNS: dict[str, tuple[str, dict]] = {
    "accel_gps_default": ("accel-gps", {"scenario.duration": 10}),
    "accel_gps_scale_factor": ("accel-gps", {"scenario.duration": 10, "truth.scale_std": 1e-3}),
    "accel_gps_gauss_markov": (
        "accel-gps",
        {"scenario.duration": 10, "truth.bias_correlation_time": 5.0},
    ),
    "accel_gps_trapezoid_drift": (
        "accel-gps",
        {"scenario.duration": 10, "scenario.integration": "trapezoid", "truth.bias_walk_std": 1e-4},
    ),
    "scale_bias_default": ("scale-bias", {"scenario.duration": 10}),
    "model_file_constant_velocity": (str(EXAMPLES / "constant_velocity.toml"), {}),
}


def run(name: str, out: Path) -> xr.Dataset:
    """Run ``RUNS[name]`` with N realizations and seed SEED into ``out``; its ``stats.nc``, loaded."""
    from kalcal.api.verification import verify
    from kalcal.scenarios.model_file.model import load_model_file
    from kalcal.scenarios import build_scenario

    target, settings = RUNS[name]
    assignments = [f"{key}={value}" for key, value in settings.items()]
    if target.endswith(".toml"):
        scenario = load_model_file(target, assignments)
    else:
        scenario = build_scenario(target, None, assignments)
    verify(scenario, N, SEED, out, long_run=0)
    with xr.open_dataset(out / "stats.nc") as dataset:
        return dataset.load()


def write_references() -> None:
    """Write every run's ``stats.nc`` into ``REFERENCE`` as ``NAME.nc``."""
    REFERENCE.mkdir(exist_ok=True)
    for name in RUNS:
        with tempfile.TemporaryDirectory() as folder:
            dataset = run(name, Path(folder) / "run")
        dataset.to_netcdf(REFERENCE / f"{name}.nc")
        print(f"wrote {REFERENCE / f'{name}.nc'}", file=sys.stderr)


if __name__ == "__main__":
    write_references()
