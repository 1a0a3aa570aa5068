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
from rich.text import Text

from kalcal import __version__
from kalcal.errors import KalcalError
from kalcal.models.registry import SCENARIOS, build_scenario

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    # plain help text: rich markup would take the units in brackets ("time [s]", "[filter]") for tags
    rich_markup_mode=None,
    context_settings={"help_option_names": ["-h", "--help"]},
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


def _print_version(value: bool) -> None:
    if value:
        console.print(f"kalcal {__version__}", markup=False, highlight=False)
        raise typer.Exit()


@app.callback()
def _options(
    version: Annotated[
        bool, typer.Option("--version", help="Print kalcal's version and exit.", is_eager=True, callback=_print_version)
    ] = False,
) -> None:
    """Kalman-filter sensor calibration with Monte Carlo verification (SI units throughout)."""


def _table(*phrases: str, **options) -> Table:
    """A table titled by ``phrases`` joined with commas, never broken inside a phrase: the table is at
    least as wide as its title, and where the console is narrower each phrase gets a line of its own."""
    title = ", ".join(phrases)
    if len(title) > console.width:
        title = ",\n".join(phrases)
    width = max(len(line) for line in title.splitlines())
    return Table(title=Text(title), min_width=min(width, console.width), **options)


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
    """Simulate one realization and write it as recorded logs.

    accel-gps: imu.csv, gps.csv, truth.csv; scale-bias: data.csv (time, reference, sensor), truth.json.
    """
    from kalcal.jobs.scale_bias import simulate_scale_bias
    from kalcal.jobs.simulate import simulate_accel_gps

    with user_errors():
        model = build_scenario(scenario, config, set_ or ())
        paths = (simulate_scale_bias if scenario == "scale-bias" else simulate_accel_gps)(model, seed, out)
    _note_nonfinite(*(path for path in paths.values() if Path(path).suffix == ".json"))
    console.print(_wrote(Path(out), paths.values()), markup=False, soft_wrap=True)


@app.command()
def calibrate(
    scenario: ScenarioArg,
    imu: Annotated[
        Optional[Path], typer.Option("--imu", help="accel-gps: accelerometer log (CSV or Parquet): time [s], accel [m/s^2].")
    ] = None,
    gps: Annotated[
        Optional[Path],
        typer.Option("--gps", help="accel-gps: GPS log (CSV or Parquet): time [s], position [m], velocity [m/s]."),
    ] = None,
    data: Annotated[
        Optional[Path],
        typer.Option("--data", help="scale-bias: log (CSV or Parquet) of a reference and a sensor column (time [s] optional)."),
    ] = None,
    reference: Annotated[str, typer.Option("--reference", help="scale-bias: the reference's column.")] = "reference",
    sensor: Annotated[str, typer.Option("--sensor", help="scale-bias: the sensor's column.")] = "sensor",
    imu_columns: Annotated[
        Optional[str], typer.Option("--imu-columns", help="accel-gps: map roles to columns, e.g. time=t,accel=ax.")
    ] = None,
    gps_columns: Annotated[
        Optional[str],
        typer.Option(
            "--gps-columns",
            help="accel-gps: map roles (time, position, velocity, position_std, velocity_std) to columns.",
        ),
    ] = None,
    init: Annotated[
        str, typer.Option("--init", help="accel-gps: first-fix (start at the first fix) or prior (the report).")
    ] = "first-fix",
    max_imu_gap: Annotated[
        float, typer.Option("--max-imu-gap", help="accel-gps: a step longer than this many sample periods is a gap.")
    ] = 5.0,
    on_gap: Annotated[str, typer.Option("--on-gap", help="accel-gps: continue (report gaps) or stop.")] = "continue",
    form: Annotated[
        str, typer.Option("--form", help="accel-gps: the filter's update form, joseph (default), standard or sqrt.")
    ] = "joseph",
    smooth: Annotated[
        bool, typer.Option("--smooth", help="accel-gps: add RTS-smoothed states and their 1-sigma to the outputs.")
    ] = False,
    out: Annotated[Path, typer.Option("--out", help="Directory for estimates.csv and summary.json.")] = Path(
        "kalcal-cal"
    ),
    strict: Annotated[
        bool, typer.Option("--strict", help="Exit with status 1 when a warning is raised or the diagnostics say inconsistent.")
    ] = False,
    set_: SetOpt = None,
    config: ConfigOpt = None,
) -> None:
    """Calibrate from logged data: accel-gps (--imu, --gps) or scale-bias (--data).

    Units are SI: time in s, position in m, velocity in m/s, acceleration and bias in m/s^2. accel-gps
    accepts irregular accelerometer samples, fixes between samples, outages and NaN fields in fixes
    (skipped and counted); the GPS log may carry position_std [m] and velocity_std [m/s] per fix.
    """
    if scenario == "scale-bias":
        if form != "joseph" or smooth:
            option = "--form" if form != "joseph" else "--smooth"
            with user_errors():
                raise KalcalError(f"{option}: not available for scale-bias (accel-gps only)")
        return _calibrate_scale_bias(
            data, reference, sensor, out, set_, config, imu is not None or gps is not None, strict
        )
    from kalcal.jobs.calibrate import calibrate_accel_gps_files

    with user_errors():
        model = build_scenario(scenario, config, set_ or (), defaults={"scenario.integration": "trapezoid"})
        missing = [name for name, path in (("--imu", imu), ("--gps", gps)) if path is None]
        if missing:
            raise KalcalError(f"{' and '.join(missing)}: required for {scenario}")
        if data is not None:
            raise KalcalError(f"--data: not used by {scenario} (it reads --imu and --gps)")
        if on_gap not in ("continue", "stop"):
            raise KalcalError(f"--on-gap: expected continue or stop, got {on_gap!r}")
        summary = calibrate_accel_gps_files(
            model,
            imu,
            gps,
            out,
            imu_columns=imu_columns,
            gps_columns=gps_columns,
            init=init,
            max_imu_gap=max_imu_gap,
            stop_on_gap=on_gap == "stop",
            form=form,
            smooth=smooth,
        )
    table = _table(f"kalcal calibrate {scenario}: {summary['fixes_used']} fixes", f"t = {summary['time']:g} s")
    table.add_column("quantity")
    table.add_column("estimate", justify="right")
    table.add_column("1-sigma", justify="right")
    table.add_column("unit")
    for name in ("bias", "scale", "position", "velocity"):
        if name in summary:
            table.add_row(name, f"{summary[name]:.6g}", f"{summary[name + '_std']:.3g}", summary["units"][name])
    console.print(table)
    if "smoothed" in summary:
        smoothed = summary["smoothed"]
        console.print(
            f"smoothed (RTS) at the first fix, t = {smoothed['time']:g} s: bias {smoothed['bias']:.6g} ± "
            f"{smoothed['bias_std']:.3g} m/s^2, position {smoothed['position']:.6g} ± {smoothed['position_std']:.3g} m",
            markup=False,
        )
    _print_warnings(summary)
    diagnostics = summary["diagnostics"]
    style = "green" if diagnostics["consistent"] else "bold red"
    console.print(f"diagnostics: [{style}]{escape(diagnostics['verdict'])}[/{style}]")
    _note_nonfinite(Path(out) / "summary.json")
    written = [Path(out) / name for name in ("estimates.csv", "summary.json", "calibration.png")]
    console.print(_wrote(Path(out), written), markup=False, soft_wrap=True)
    if strict and (summary["warnings"] or not diagnostics["consistent"]):
        raise typer.Exit(1)


def _print_warnings(summary: dict) -> None:
    """Each of the summary's warnings as one line on stderr."""
    for warning in summary["warnings"]:
        error_console.print(f"kalcal: warning: {warning['message']}", markup=False)


def _calibrate_scale_bias(data, reference, sensor, out, set_, config, imu_or_gps: bool, strict: bool = False) -> None:
    """``kalcal calibrate scale-bias``: the scale error and bias of a sensor against a reference."""
    from kalcal.jobs.scale_bias import calibrate_scale_bias_file

    with user_errors():
        model = build_scenario("scale-bias", config, set_ or ())
        if data is None:
            raise KalcalError("--data: required for scale-bias (a log with a reference and a sensor column)")
        if imu_or_gps:
            raise KalcalError("--imu/--gps: not used by scale-bias (it reads --data)")
        summary = calibrate_scale_bias_file(model, data, out, reference=reference, sensor=sensor)
    unit = summary["units"]["bias"]
    table = _table(f"kalcal calibrate scale-bias: {summary['samples_used']} samples", f"t = {summary['time']:g} s")
    table.add_column("quantity")
    table.add_column("estimate", justify="right")
    table.add_column("1-sigma", justify="right")
    table.add_column("unit")
    for name, value, std, unit_ in (
        ("scale_error", summary["scale_error"], summary["scale_error_std"], "1"),
        ("bias", summary["bias"], summary["bias_std"], unit),
        ("theta1", summary["theta"][0], summary["theta_std"][0], "1"),
        ("theta2", summary["theta"][1], summary["theta_std"][1], unit),
    ):
        table.add_row(name, f"{value:.6g}", f"{std:.3g}", unit_)
    console.print(table)
    _print_warnings(summary)
    _note_nonfinite(Path(out) / "summary.json")
    console.print(_wrote(Path(out), [Path(out) / "estimates.csv", Path(out) / "summary.json"]), markup=False, soft_wrap=True)
    if strict and summary["warnings"]:
        raise typer.Exit(1)


def _progress_bar(title: str):
    """A rich progress bar on a terminal, nothing otherwise: returns (context manager, callback or None).

    The callback is a job's ``progress(stage, done, total)`` (:mod:`kalcal.jobs.progress`): the bar shows
    the stage, its count of units and its time.
    """
    if not error_console.is_terminal:
        return contextlib.nullcontext(), None
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    from kalcal.jobs.progress import STAGES

    bar = Progress(
        TextColumn("{task.description}", markup=False),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[unit]}", markup=False),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=error_console,
        transient=True,
    )
    task = bar.add_task(title, total=None, unit="")

    def update(stage: str, done: int, total: int) -> None:
        bar.update(task, description=f"{title}: {stage}", completed=done, total=total, unit=STAGES.get(stage, ""))

    return bar, update


def _wrote(out: Path, paths) -> str:
    """One line naming what a job wrote: ``wrote OUT/: summary.json, stats.nc, report.html, figures/``."""
    names = []
    for path in paths:
        path = Path(path)
        try:
            name = str(path.relative_to(out))
        except ValueError:  # not inside the output folder: its full path
            name = str(path)
        names.append(name + ("/" if path.is_dir() else ""))
    return f"wrote {out}/: {', '.join(names)}"


def _note_nonfinite(*paths) -> None:
    """For each JSON file written whose ``nonfinite.count`` is not 0 (:func:`kalcal.io.results.write_json`),
    one line: ``note: 3 values in summary.json are not finite and written as null: tests.statistic (2), ...``."""
    import json

    for path in paths:
        try:
            nonfinite = json.loads(Path(path).read_text(encoding="utf-8")).get("nonfinite") or {}
        except (OSError, ValueError):
            continue
        count = nonfinite.get("count", 0)
        if count:
            fields = ", ".join(f"{name} ({n})" for name, n in nonfinite.get("fields", {}).items())
            value, verb = ("value", "is") if count == 1 else ("values", "are")
            console.print(
                f"note: {count} {value} in {path} {verb} not finite and written as null: {fields}",
                markup=False,
                soft_wrap=True,
            )


def _print_checks(summary: dict) -> None:
    """The checks as one table, then one paragraph per failed check saying why."""
    table = _table(
        f"kalcal verify {summary['scenario']}: {summary['realizations']:,} realizations ({summary['engine']}) "
        f"in {summary['timing']['monte_carlo_s']:.2f} s",
        f"verdict: {summary['verdict'].upper()}",
    )
    table.add_column("check")
    table.add_column("statistic", justify="right")
    table.add_column("bounds", justify="right")
    table.add_column("p-value", justify="right")
    table.add_column("result")
    from kalcal.verify.text import CHECK_PVALUE_FIELD, check_bounds_text, fmt, pvalue_text, written_nan

    nan = written_nan(summary, CHECK_PVALUE_FIELD)
    for test in summary["tests"]:
        result = "[green]pass[/green]" if test["passed"] else "[bold red]FAIL[/bold red]"
        # every part's bounds (the covariance check: element-wise and centered NEES), as on the page
        table.add_row(
            escape(test["name"]),
            fmt(test["statistic"]),
            escape(check_bounds_text(test)),
            pvalue_text(test["pvalue"], nan).removeprefix("p = "),
            result,
        )
    console.print(table)
    for test in summary["tests"]:
        if not test["passed"]:
            console.print(f"[bold]{test['name']}[/bold]: {escape(test['detail'])}")


def _verify_scenario(scenario: str, config, assignments, engine: str, long_run):
    """A built-in scenario by name, or a model file (a path ending in .toml) with what it supports."""
    from kalcal.models.custom import is_model_file, load_model_file

    if not is_model_file(scenario):
        return build_scenario(scenario, config, assignments)
    if engine == "sampled":
        raise KalcalError(f"--engine: 'sampled' is not available for a model file ({scenario}); use the exact engine")
    if long_run:
        raise KalcalError(f"--long-run: not available for a model file ({scenario}); set updates in the file instead")
    return load_model_file(scenario, assignments, config=config)


@app.command()
def verify(
    scenario: Annotated[
        str, typer.Argument(help=f"Scenario: {', '.join(SCENARIOS)}, or a model file (.toml, docs/custom-models.md).")
    ] = "accel-gps",
    n: Annotated[int, typer.Option("-n", "--realizations", help="Monte Carlo realizations (at least 100).")] = 300_000,
    seed: Annotated[int, typer.Option("--seed", help="Root seed; the same seed gives the same numbers.")] = 0,
    out: Annotated[Path, typer.Option("--out", help="Directory for summary.json, stats.nc and the report.")] = Path(
        "kalcal-out"
    ),
    engine: Annotated[str, typer.Option("--engine", help="exact (update-rate sampling) or sampled (every sample).")] = "exact",
    confidence: Annotated[float, typer.Option("--confidence", help="Family-wise confidence of each check.")] = 0.99,
    threads: Annotated[Optional[int], typer.Option("--threads", help="Local threads (default: all cores).")] = None,
    workers: Annotated[
        Optional[int], typer.Option("--workers", help="Run on a local Dask cluster of this many processes.")
    ] = None,
    scheduler: Annotated[
        Optional[str], typer.Option("--scheduler", help="Run on an existing Dask cluster (e.g. tcp://host:8786).")
    ] = None,
    batch_size: Annotated[
        Optional[int], typer.Option("--batch-size", help="Realizations per task (whole blocks of 4096).")
    ] = None,
    checkpoint: Annotated[
        Optional[Path], typer.Option("--checkpoint", help="Save progress here; rerunning the command resumes.")
    ] = None,
    strict: Annotated[bool, typer.Option("--strict", help="Exit with status 1 when a check fails.")] = False,
    long_run: Annotated[
        Optional[float],
        typer.Option("--long-run", help="Seconds of the extra long-horizon mean-error study (0: none; accel-gps: 120)."),
    ] = None,
    form: Annotated[
        str, typer.Option("--form", help="The filter's update form: joseph (default), standard or sqrt.")
    ] = "joseph",
    no_report: Annotated[bool, typer.Option("--no-report", help="Do not draw the figures and report.html.")] = False,
    realization: Annotated[int, typer.Option("--realization", help="Realization shown in the single-run figures.")] = 0,
    set_: SetOpt = None,
    config: ConfigOpt = None,
) -> None:
    """Verify the filter with a Monte Carlo: mean error, covariance, orthogonality, whiteness, NIS."""
    import shlex

    from kalcal.jobs.verify import check_arguments
    from kalcal.jobs.verify import verify as run_verify
    from kalcal.montecarlo.distributed import dask_client

    with user_errors():
        model = _verify_scenario(scenario, config, set_ or (), engine, long_run)
        if threads is not None and threads < 1:
            raise KalcalError(f"--threads: expected a positive number, got {threads}")
        # before any cluster starts: a bad argument costs nothing
        check_arguments(
            model, n, engine=engine, confidence=confidence, long_run=long_run, batch_size=batch_size, form=form
        )
        bar, update = _progress_bar(f"{scenario} x {n:,}")
        with dask_client(workers, scheduler) as client, bar:
            outcome = run_verify(
                model,
                n,
                seed,
                out,
                engine=engine,
                confidence=confidence,
                workers=threads,
                progress=update,
                command=shlex.join(["kalcal", *sys.argv[1:]]),
                long_run=long_run,
                client=client,
                batch_size=batch_size,
                checkpoint=checkpoint,
                form=form,
                report=not no_report,
                realization=realization,
            )
    _print_checks(outcome.summary)
    pair = outcome.summary["residual_correlation"]
    if pair is not None:  # only runs that have the source report's pair of updates
        rows = ", ".join(
            "[" + ", ".join(f"{m:.3g} ± {se:.2g}" for m, se in zip(row, errors)) + "]"
            for row, errors in zip(pair["matrix"], pair["standard_error"])
        )
        console.print(
            f"E[r_k r_j^T] at t_k = {pair['k_time']:g} s, t_j = {pair['j_time']:g} s (± standard error): [{rows}]",
            markup=False,
            soft_wrap=True,
        )
    _note_nonfinite(outcome.paths["summary"])
    order = ("summary", "stats", "stats_long", "report", "figures")
    written = [outcome.paths[key] for key in order if key in outcome.paths]
    written += [path for key, path in outcome.paths.items() if key not in order]
    console.print(_wrote(Path(out), written), markup=False, soft_wrap=True)
    if strict and outcome.summary["verdict"] != "pass":
        raise typer.Exit(1)


@app.command()
def sweep(
    scenario: Annotated[str, typer.Argument(help=f"Scenario: {', '.join(SCENARIOS)}.")] = "accel-gps",
    n: Annotated[int, typer.Option("-n", "--realizations", help="Monte Carlo realizations per value.")] = 100_000,
    seed: Annotated[int, typer.Option("--seed", help="Root seed, the same for every value.")] = 0,
    out: Annotated[Path, typer.Option("--out", help="Directory for sweep.csv, sweep.png and one run per value.")] = Path(
        "kalcal-sweep"
    ),
    engine: Annotated[str, typer.Option("--engine", help="exact or sampled.")] = "exact",
    threads: Annotated[Optional[int], typer.Option("--threads", help="Local threads (default: all cores).")] = None,
    workers: Annotated[Optional[int], typer.Option("--workers", help="Local Dask cluster of this many processes.")] = None,
    scheduler: Annotated[Optional[str], typer.Option("--scheduler", help="Existing Dask cluster address.")] = None,
    set_: SetOpt = None,
    config: ConfigOpt = None,
) -> None:
    """Verify once per value of one setting (--set key=v1,v2,...) and draw the tuning curve."""
    from kalcal.jobs.sweep import split_sweep, sweep_cells
    from kalcal.jobs.sweep import sweep as run_sweep
    from kalcal.models.settings import parse_assignments
    from kalcal.montecarlo.distributed import dask_client

    with user_errors():
        key, values, fixed = split_sweep(parse_assignments(set_ or ()))
        model = build_scenario(scenario, config, [f"{k}={v}" for k, v in fixed.items()])
        sweep_cells(model, key, values, n, engine=engine, long_run=0)  # every value checked before any cluster
        with dask_client(workers, scheduler) as client:
            result = run_sweep(
                model, key, values, n, seed, out, engine=engine, workers=threads, client=client, long_run=0
            )
    table = _table(f"kalcal sweep {scenario}: {key}", f"{n:,} realizations per value")
    table.add_column(key, justify="right")
    checks = [c[: -len("_passed")] for c in result.table.columns if c.endswith("_passed")]
    for check in checks:
        table.add_column(check, justify="right")
    for _, row in result.table.iterrows():
        cells = [f"{row[f'{c}_statistic']:.4g}" + ("" if row[f"{c}_passed"] else " [red]x[/red]") for c in checks]
        table.add_row(str(row[key]), *cells)
    console.print(table)
    runs = sorted(path.parent for path in Path(out).glob("*=*/summary.json"))
    _note_nonfinite(result.paths["summary"], *(run / "summary.json" for run in runs))
    written = [result.paths[key] for key in ("summary", "table", "figure")] + runs
    console.print(_wrote(Path(out), written), markup=False, soft_wrap=True)


@app.command()
def noise(
    imu: Annotated[
        Optional[Path], typer.Option("--imu", help="Static accelerometer log (CSV or Parquet): time [s], accel [m/s^2].")
    ] = None,
    out: Annotated[Path, typer.Option("--out", help="Directory for summary.json, allan.csv, allan.png, filter.toml.")] = Path(
        "kalcal-noise"
    ),
    imu_columns: Annotated[
        Optional[str], typer.Option("--imu-columns", help="Map roles to columns, e.g. time=t,accel=ax.")
    ] = None,
    strict: Annotated[
        bool, typer.Option("--strict", help="Refuse (exit status 2, nothing written) a log that does not look static.")
    ] = False,
) -> None:
    """Identify accelerometer noise from a static log: Allan deviation, N, B, K and the [filter] settings.

    N (velocity random walk, m/s/sqrt(s)) from the -1/2 slope, B (bias instability, m/s^2) from the flat
    minimum, K (rate random walk, m/s^2/sqrt(s)) from the +1/2 slope; filter.toml holds accel_noise_std
    = N sqrt(rate) and, where K is seen, bias_walk_std = K sqrt(dt), for calibrate --config.
    """
    from rich import box

    from kalcal.jobs.noise import identify_noise_file

    with user_errors():
        if imu is None:
            raise KalcalError("--imu: required (a static accelerometer log: time [s], accel [m/s^2])")
        summary = identify_noise_file(imu, out, imu_columns=imu_columns, strict=strict)
    table = _table(
        f"kalcal noise: {summary['samples']:,} samples at {summary['rate']['value']:.6g} Hz",
        f"{summary['duration']['value']:.6g} s",
        box=box.SIMPLE_HEAD,
        pad_edge=False,
    )
    table.add_column("quantity", no_wrap=True)
    table.add_column("value", justify="right", no_wrap=True)
    table.add_column(f"{100 * summary['confidence']:g}% interval", justify="right", no_wrap=True)
    table.add_column("unit", no_wrap=True)
    regions = []
    for name in ("accel_noise_std", "velocity_random_walk", "bias_instability", "rate_random_walk", "bias_walk_std"):
        item = summary[name]
        if item["identified"]:
            table.add_row(name, f"{item['value']:.4g}", f"{item['ci_low']:.3g}-{item['ci_high']:.3g}", item["unit"])
            if name in ("velocity_random_walk", "bias_instability", "rate_random_walk"):
                first, last = item["tau_range"]
                regions.append(f"{name} at tau = {first:.3g}" + ("" if first == last else f"-{last:.3g}") + " s")
        else:
            table.add_row(name, "not seen", f"< {item['upper_bound']:.3g}", item["unit"])
    console.print(table)
    if regions:
        console.print("read off the curve: " + "; ".join(regions), markup=False)
    for note in summary["notes"]:
        console.print(f"note: {escape(note)}")
    _print_warnings(summary)
    files = summary["files"]
    _note_nonfinite(files["summary"])
    written = [files[key] for key in ("summary", "allan", "plot", "filter")]
    console.print(_wrote(Path(out), written), markup=False, soft_wrap=True)


@app.command()
def report(
    directory: Annotated[Path, typer.Argument(help="A directory written by kalcal verify.")],
    realization: Annotated[int, typer.Option("--realization", help="Realization shown in the single-run figures.")] = 0,
) -> None:
    """Redraw the figures and report.html of a verification run from its summary.json and stats.nc."""
    from kalcal.jobs.report import FIGURE_DIR, render_report

    with user_errors():
        bar, update = _progress_bar(str(directory))
        with bar:
            page = render_report(directory, realization=realization, progress=update)
    console.print(_wrote(Path(directory), [page, Path(directory) / FIGURE_DIR]), markup=False, soft_wrap=True)


def _named_files(args: list[str]) -> list[str]:
    """The existing files named on the command line (``--opt PATH``, ``--opt=PATH``, arguments): inputs."""
    candidates = [part for arg in args for part in (arg, arg.partition("=")[2]) if part]
    return [c for c in candidates if Path(c).is_file()]


def main() -> None:
    """The console script: the app, with click's own usage errors (a bad option value, a missing
    argument) as one line on stderr and exit status 2, like every other bad input.

    SIGINT (Ctrl-C) and SIGTERM stop a run with one line, ``kalcal: interrupted``, and exit status
    128 + the signal (130, 143), after the run's staged outputs are removed (its --out folder is left as
    it was). No file named on the command line is ever removed or replaced by the outputs.
    """
    # typer carries its own copy of click: TyperException is the base of its usage errors
    from typer.exceptions import TyperException

    from kalcal.interrupts import Interrupted, raise_on_signals
    from kalcal.io.outputs import protected

    try:
        with raise_on_signals(), protected(*_named_files(sys.argv[1:])):
            code = app(prog_name="kalcal", standalone_mode=False)
    except Interrupted as exc:
        error_console.print("kalcal: interrupted", markup=False)
        sys.exit(exc.exit_status)
    except typer.Abort:
        error_console.print("kalcal: interrupted", markup=False)
        sys.exit(130)
    except TyperException as exc:
        if type(exc).__name__ == "NoArgsIsHelpError":  # bare `kalcal`: the help, as the user asked for nothing
            app(["--help"], prog_name="kalcal")
        message = exc.format_message() if hasattr(exc, "format_message") else str(exc)
        error_console.print(f"kalcal: error: {message}", markup=False)
        sys.exit(getattr(exc, "exit_code", 2) or 2)
    sys.exit(code or 0)


if __name__ == "__main__":
    main()
