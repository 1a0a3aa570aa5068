"""``kalcal calibrate``: a sensor's bias (and scale) from logged data, through :func:`kalcal.calibrate`."""

from pathlib import Path
from typing import Annotated, Optional

import typer

from kalcal.cli import _common
from kalcal.cli._common import ConfigOpt, TopicOpt, ScenarioArg, SetOpt, escape, settings_of, user_errors


def calibrate(
    scenario: ScenarioArg,
    imu: Annotated[
        Optional[Path], typer.Option("--imu", help="accel-gps: accelerometer log (CSV, Parquet, ROS bag, ULog; a topic's columns TOPIC.FIELD): time [s], accel [m/s^2].")
    ] = None,
    gps: Annotated[
        Optional[Path],
        typer.Option("--gps", help="accel-gps: GPS log (CSV, Parquet, ROS bag, ULog): time [s], position [m], velocity [m/s]."),
    ] = None,
    data: Annotated[
        Optional[Path],
        typer.Option("--data", help="scale-bias: log (CSV, Parquet, ROS bag, ULog) of a reference and a sensor column (time [s] optional); a model file: a log in its [data] layout."),
    ] = None,
    reference: Annotated[str, typer.Option("--reference", help="scale-bias: the reference's column.")] = "reference",
    sensor: Annotated[str, typer.Option("--sensor", help="scale-bias: the sensor's column.")] = "sensor",
    prior: Annotated[
        Optional[str],
        typer.Option("--prior", help="scale-bias: diffuse (theta from the log alone) or settings (the filter's prior of a, b)."),
    ] = None,
    imu_columns: Annotated[
        Optional[str], typer.Option("--imu-columns", help="accel-gps: map roles to columns, e.g. time=t,accel=ax; imu-3axis: the three axes' columns, e.g. ax,ay,az (default acc_x,acc_y,acc_z).")
    ] = None,
    poses: Annotated[
        Optional[Path],
        typer.Option("--poses", help="imu-3axis: JSON of static poses' sample ranges {\"x_p\": {\"start\": i, \"end\": j}, ...}; face names: procedure (a), others (b); without it a static detector finds them."),
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
        bool, typer.Option("--smooth", help="accel-gps, a model file: add RTS-smoothed states and their 1-sigma to the outputs.")
    ] = False,
    windows: Annotated[
        int,
        typer.Option("--windows", help="Split the log into this many windows and test their estimates' agreement (1: off)."),
    ] = 2,
    gate: Annotated[
        Optional[float],
        typer.Option(
            "--gate",
            help="accel-gps: reject a fix whose NIS exceeds the chi-square quantile at this confidence (e.g. 0.999); off by default.",
        ),
    ] = None,
    settings_sigma: Annotated[
        bool,
        typer.Option(
            "--settings-sigma/--no-settings-sigma",
            help="accel-gps: also give the bias sigma over the noise settings the log cannot reject (on; about a fit's time).",
        ),
    ] = True,
    out: Annotated[Path, typer.Option("--out", help="Directory for estimates.csv and summary.json.")] = Path(
        "kalcal-cal"
    ),
    strict: Annotated[
        bool, typer.Option("--strict", help="Exit with status 1 when a warning is raised or the diagnostics say inconsistent.")
    ] = False,
    set_: SetOpt = None,
    config: ConfigOpt = None,
    topic: TopicOpt = None,
) -> None:
    """Calibrate from logged data: accel-gps (--imu, --gps), scale-bias (--data), imu-3axis (--imu, --poses) or a
    model file (MODEL.toml --data LOG).

    Units are SI: time in s, position in m, velocity in m/s, acceleration and bias in m/s^2. accel-gps
    accepts irregular accelerometer samples, fixes between samples, outages and NaN fields in fixes
    (skipped and counted); the GPS log may carry position_std [m] and velocity_std [m/s] per fix.
    """
    from kalcal.api.calibrate import calibrate as run_calibrate

    with user_errors():
        result = run_calibrate(
            scenario,
            imu=imu,
            gps=gps,
            data=data, topic=topic,
            settings=settings_of(set_),
            config=config,
            reference=reference,
            sensor=sensor,
            imu_columns=imu_columns,
            gps_columns=gps_columns,
            init=init,
            max_imu_gap=max_imu_gap,
            on_gap=on_gap,
            form=form,
            smooth=smooth,
            prior=prior,
            windows=windows,
            gate=gate,
            settings_sigma=settings_sigma,
            poses=poses,
            out=out,
        )
    summary = result.summary
    title, caption = result.title()
    table = _common._table(title, caption)
    table.add_column("quantity")
    table.add_column("estimate", justify="right")
    table.add_column("1-sigma", justify="right")
    table.add_column("unit")
    for name, value, sigma, trusted, unit in result.table():
        shown = f"{sigma:.3g}"
        table.add_row(name, f"{value:.6g}", shown if trusted else f"[bold red]{shown} NOT trusted[/bold red]", unit)
    for row in result.extra_rows():
        table.add_row(*row)
    console = _common.console
    console.print(table)
    for text, _ in result.lines():
        console.print(text, markup=False)
    _common._print_warnings(summary)
    diagnostics = result.diagnostics_line()
    if diagnostics is not None:
        style = "green" if diagnostics[1] else "bold red"
        console.print(f"diagnostics: [{style}]{escape(diagnostics[0])}[/{style}]")
    _print_stability(summary)
    _common._note_nonfinite(result.paths["summary.json"])
    _common.print_wrote(Path(out), list(result.paths.values()))
    if strict and result.strict_failed():
        raise typer.Exit(1)


def _print_stability(summary: dict) -> None:
    """The stability test's one line: green when stable, red when not, plain when it did not run."""
    stability = summary["stability"]
    style = {True: "green", False: "bold red"}.get(stability["stable"])
    text = escape(stability["sentence"])
    _common.console.print(f"stability: [{style}]{text}[/{style}]" if style else f"stability: {text}")
