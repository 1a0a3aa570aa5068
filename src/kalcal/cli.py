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
from rich.markup import escape
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
    except (KalcalError, OSError) as exc:
        # OSError: an output path that cannot be written (a file where a directory should be, no permission)
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


def _progress_bar(total_label: str):
    """A rich progress bar on a terminal, nothing otherwise: returns (context manager, callback or None)."""
    if not error_console.is_terminal:
        return contextlib.nullcontext(), None
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    bar = Progress(
        TextColumn(total_label),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=error_console,
        transient=True,
    )
    task = bar.add_task(total_label, total=None)

    def update(done: int, total: int) -> None:
        bar.update(task, completed=done, total=total)

    return bar, update


def _print_checks(summary: dict) -> None:
    """The checks as one table, then one paragraph per failed check saying why."""
    table = Table(
        title=(
            f"kalcal verify {summary['scenario']}: {summary['realizations']:,} realizations "
            f"({summary['engine']}) in {summary['timing']['monte_carlo_s']:.2f} s, verdict: {summary['verdict'].upper()}"
        ),
    )
    table.add_column("check")
    table.add_column("statistic", justify="right")
    table.add_column("bounds", justify="right")
    table.add_column("result")
    for test in summary["tests"]:
        lower = "" if test["lower"] is None else f"{test['lower']:.4g} .. "
        result = "[green]pass[/green]" if test["passed"] else "[bold red]FAIL[/bold red]"
        table.add_row(test["name"], f"{test['statistic']:.4g}", f"{lower}{test['upper']:.4g}", result)
    console.print(table)
    for test in summary["tests"]:
        if not test["passed"]:
            console.print(f"[bold]{test['name']}[/bold]: {escape(test['detail'])}")


@app.command()
def verify(
    scenario: Annotated[str, typer.Argument(help=f"Scenario: {', '.join(SCENARIOS)}.")] = "accel-gps",
    n: Annotated[int, typer.Option("-n", "--realizations", help="Monte Carlo realizations.")] = 300_000,
    seed: Annotated[int, typer.Option("--seed", help="Root seed; the same seed gives the same numbers.")] = 0,
    out: Annotated[Path, typer.Option("--out", help="Directory for summary.json, stats.nc and the report.")] = Path(
        "kalcal-out"
    ),
    engine: Annotated[str, typer.Option("--engine", help="exact (update-rate sampling) or sampled (every sample).")] = "exact",
    confidence: Annotated[float, typer.Option("--confidence", help="Family-wise confidence of each check.")] = 0.99,
    workers: Annotated[Optional[int], typer.Option("--workers", help="Threads (default: all cores).")] = None,
    strict: Annotated[bool, typer.Option("--strict", help="Exit with status 1 when a check fails.")] = False,
    long_run: Annotated[
        Optional[float],
        typer.Option("--long-run", help="Seconds of the extra long-horizon mean-error study (0: none; accel-gps: 120)."),
    ] = None,
    no_report: Annotated[bool, typer.Option("--no-report", help="Do not draw the figures and report.html.")] = False,
    realization: Annotated[int, typer.Option("--realization", help="Realization shown in the single-run figures.")] = 0,
    set_: SetOpt = None,
    config: ConfigOpt = None,
) -> None:
    """Verify the filter with a Monte Carlo: mean error, covariance, orthogonality, whiteness, NIS."""
    import shlex

    from kalcal.jobs.verify import verify as run_verify

    with user_errors():
        model = build_scenario(scenario, config, set_ or ())
        if workers is not None and workers < 1:
            raise KalcalError(f"--workers: expected a positive number, got {workers}")
        bar, update = _progress_bar(f"{scenario} x {n:,}")
        with bar:
            outcome = run_verify(
                model,
                n,
                seed,
                out,
                engine=engine,
                confidence=confidence,
                workers=workers,
                progress=update,
                command=shlex.join(["kalcal", *sys.argv[1:]]),
                long_run=long_run,
            )
        if not no_report:
            from kalcal.jobs.report import render_report

            outcome.paths["report"] = render_report(Path(out), realization=realization)
    _print_checks(outcome.summary)
    pair = outcome.summary["residual_correlation"]
    console.print(
        f"E[r_k r_j^T] at k = {pair['k_time']:g} s, j = {pair['j_time']:g} s: "
        f"{pair['matrix'].tolist()} (standard errors {pair['standard_error'].round(6).tolist()})",
        markup=False,
    )
    for path in outcome.paths.values():
        console.print(f"wrote {path}")
    if strict and outcome.summary["verdict"] != "pass":
        raise typer.Exit(1)


@app.command()
def report(
    directory: Annotated[Path, typer.Argument(help="A directory written by kalcal verify.")],
    realization: Annotated[int, typer.Option("--realization", help="Realization shown in the single-run figures.")] = 0,
) -> None:
    """Redraw the figures and report.html of a verification run from its summary.json and stats.nc."""
    from kalcal.jobs.report import render_report

    with user_errors():
        page = render_report(directory, realization=realization)
    console.print(f"wrote {page}")


def main() -> None:  # pragma: no cover - the console script
    app(prog_name="kalcal")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
