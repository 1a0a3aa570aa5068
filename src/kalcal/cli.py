"""The ``kalcal`` command line: parse, call a job, print. No numerics here.

Units everywhere are SI: time in s, position in m, velocity in m/s, acceleration and bias in m/s^2.
Bad input of any kind is one line on stderr and exit status 2.
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.console import Console
from rich.table import Table

from kalcal.errors import KalcalError
from kalcal.models.registry import SCENARIOS, build_scenario

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    help="Kalman-filter sensor calibration with Monte Carlo verification (SI units throughout).",
)
console = Console()
error_console = Console(stderr=True, highlight=False, soft_wrap=True)

ScenarioArg = Annotated[str, typer.Argument(help=f"Scenario: {', '.join(SCENARIOS)}.")]
SetOpt = Annotated[
    Optional[list[str]],
    typer.Option("--set", help="Override a setting, section.key=value (repeatable), e.g. truth.bias_std=0.2."),
]
ConfigOpt = Annotated[Optional[Path], typer.Option("--config", help="TOML file of [scenario], [truth], [filter] settings.")]


@contextlib.contextmanager
def user_errors() -> Iterator[None]:
    """Turn a KalcalError into one line on stderr and exit status 2."""
    try:
        yield
    except KalcalError as exc:
        error_console.print(f"kalcal: error: {exc}", markup=False)
        raise typer.Exit(2) from None


@app.command()
def simulate(
    scenario: ScenarioArg,
    out: Annotated[Path, typer.Option("--out", help="Directory for the logs.")] = Path("kalcal-sim"),
    seed: Annotated[int, typer.Option("--seed", help="Seed of the random generator.")] = 0,
    set_: SetOpt = None,
    config: ConfigOpt = None,
) -> None:
    """Simulate one realization and write it as recorded logs (imu.csv, gps.csv, truth.csv)."""
    from kalcal.jobs.simulate import simulate_accel_gps

    with user_errors():
        model = build_scenario(scenario, config, set_ or ())
        paths = simulate_accel_gps(model, seed, out)
    for name, path in paths.items():
        console.print(f"wrote {name:5s} {path}")


@app.command()
def calibrate(
    scenario: ScenarioArg,
    imu: Annotated[Path, typer.Option("--imu", help="Accelerometer log (CSV or Parquet): time [s], accel [m/s^2].")],
    gps: Annotated[Path, typer.Option("--gps", help="GPS log (CSV or Parquet): time [s], position [m], velocity [m/s].")],
    out: Annotated[Path, typer.Option("--out", help="Directory for estimates.csv and summary.json.")] = Path(
        "kalcal-cal"
    ),
    set_: SetOpt = None,
    config: ConfigOpt = None,
) -> None:
    """Calibrate the accelerometer bias from logged data (integration defaults to trapezoid for logs)."""
    from kalcal.jobs.calibrate import calibrate_accel_gps_files

    with user_errors():
        model = build_scenario(scenario, config, set_ or (), defaults={"scenario.integration": "trapezoid"})
        summary = calibrate_accel_gps_files(model, imu, gps, out)
    table = Table(title=f"kalcal calibrate {scenario}: {summary['fixes_used']} fixes, t = {summary['time']:g} s")
    table.add_column("quantity")
    table.add_column("estimate", justify="right")
    table.add_column("1-sigma", justify="right")
    table.add_column("unit")
    for name, unit in (("bias", "m/s^2"), ("position", "m"), ("velocity", "m/s")):
        table.add_row(name, f"{summary[name]:.6g}", f"{summary[name + '_std']:.3g}", unit)
    console.print(table)
    console.print(f"wrote {Path(out) / 'estimates.csv'} and {Path(out) / 'summary.json'}")


def main() -> None:  # pragma: no cover - the console script
    app(prog_name="kalcal")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
