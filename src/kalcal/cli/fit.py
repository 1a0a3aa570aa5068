"""``kalcal fit``: a filter's noise settings fitted to one log by maximum likelihood, through :func:`kalcal.fit`."""

from pathlib import Path
from typing import Annotated, Optional

import typer

from kalcal.cli import _common
from kalcal.cli._common import ConfigOpt, TopicOpt, ScenarioArg, SetOpt, escape, settings_of, user_errors


def _derived_row(result, name: str, p) -> tuple[str, str, str, str] | None:
    """The row under a fitted setting: the same estimate in the form the scenario also gives it
    (:attr:`~kalcal.fitting.result.FitResult.derived`; accel-gps: a density's per-sample std at the log's rate)."""
    shown = result.derived.get(name)
    if shown is None or not p.identified or p.trades_off:
        return None
    low, high = shown.ci_low, shown.ci_high
    interval = f"[0, {'—' if high is None else f'{high:.4g}'}]" if p.at_bound else (
        f"[{'—' if low is None else f'{low:.4g}'}, {'—' if high is None else f'{high:.4g}'}]")
    return f"  = {shown.name}", f"{shown.value:.4g}", interval, shown.unit


def _bootstrap_table(result):
    """The bootstrap beside the likelihood intervals: per setting the likelihood interval, the percentile
    interval, the bootstrap standard error and the bias (+- its Monte Carlo error), or "not applicable" and why."""
    from kalcal.fitting.result import bootstrap_note, likelihood_text, percentile_text

    boot = result.bootstrap
    table = _common._table(
        f"parametric bootstrap: {boot.replicates} logs simulated from the fit and refitted (seed {boot.seed})",
        f"{boot.failed} refit(s) not converged",
        f"{boot.seconds:.3g} s",
    )
    for column in ("setting", f"{result.confidence:.0%} {result.interval_method}", f"{boot.confidence:.0%} percentile", "boot se", "bias", "note"):
        table.add_column(column, justify="left" if column in ("setting", "note") else "right")
    for name, b in boot.parameters.items():
        likelihood = likelihood_text(result.parameters[name])
        if b.se is None:
            table.add_row(escape(name), likelihood, "not applicable", "—", "—", escape(b.reason))
            continue
        interval = percentile_text(b)
        table.add_row(escape(name), likelihood, interval, f"{b.se:.3g}", f"{b.bias:.3g} ± {b.bias_se:.2g}",
                      escape(bootstrap_note(b)))
    return table


def fit(
    scenario: ScenarioArg,
    imu: Annotated[
        Optional[Path], typer.Option("--imu", help="accel-gps: accelerometer log (CSV, Parquet, ROS bag, ULog; a topic's columns TOPIC.FIELD): time [s], accel [m/s^2].")
    ] = None,
    gps: Annotated[
        Optional[Path],
        typer.Option("--gps", help="accel-gps: GPS log: time [s], position [m], velocity [m/s] (position_std, velocity_std)."),
    ] = None,
    data: Annotated[
        Optional[Path], typer.Option("--data", help="scale-bias: log of a reference and a sensor column (time [s] optional); a model file: the log its [data] table lays out.")
    ] = None,
    free: Annotated[
        Optional[str],
        typer.Option("--free", help="Settings to fit, KEY,KEY... (e.g. filter.accel_noise_density,filter.bias_walk_density; a model file's filter.w, filter.v.2, filter.phi.1.1)."),
    ] = None,
    profile: Annotated[
        bool, typer.Option("--profile", help="Intervals from the profile likelihood instead of the observed information.")
    ] = False,
    gate: Annotated[
        Optional[float], typer.Option("--gate", help="accel-gps: chi-square innovation gate at this confidence (off by default).")
    ] = None,
    init: Annotated[
        str, typer.Option("--init", help="accel-gps: first-fix (start at the first fix) or prior.")
    ] = "first-fix",
    reference: Annotated[str, typer.Option("--reference", help="scale-bias: the reference's column.")] = "reference",
    sensor: Annotated[str, typer.Option("--sensor", help="scale-bias: the sensor's column.")] = "sensor",
    imu_columns: Annotated[Optional[str], typer.Option("--imu-columns", help="accel-gps: map roles to columns.")] = None,
    gps_columns: Annotated[Optional[str], typer.Option("--gps-columns", help="accel-gps: map roles to columns.")] = None,
    bootstrap: Annotated[
        int, typer.Option("--bootstrap", help="B >= 39 (the fewest whose 95% percentile interval has its ends among the refits: the smallest and largest of 39), at most 100000: also a parametric bootstrap of B logs simulated from the fit and refitted (percentile intervals, bootstrap se, bias; fit-bootstrap.png).")
    ] = 0,
    seed: Annotated[Optional[int], typer.Option("--seed", help="The bootstrap's root seed (default 0); the same seed gives the same intervals.")] = None,
    threads: Annotated[Optional[int], typer.Option("--threads", help="The bootstrap's local threads (default: all cores).")] = None,
    workers: Annotated[
        Optional[int], typer.Option("--workers", help="Run the bootstrap on a local Dask cluster of this many processes.")
    ] = None,
    scheduler: Annotated[
        Optional[str], typer.Option("--scheduler", help="Run the bootstrap on an existing Dask cluster (e.g. tcp://host:8786).")
    ] = None,
    out: Annotated[Path, typer.Option("--out", help="Directory for fit.json, filter.toml (a model file's: model.toml) and fit.png.")] = Path("kalcal-fit"),
    set_: SetOpt = None,
    config: ConfigOpt = None,
    topic: TopicOpt = None,
) -> None:
    """Fit noise settings to a log by maximum likelihood: accel-gps (--imu, --gps), scale-bias or a model file (--data).

    Writes fit.json (estimates, 95% intervals, log L, AIC, adequacy), filter.toml (for --config of
    calibrate and verify; the noise as rate-free densities), fit.png and, for accel-gps, Kalibr's imu.yaml. `kalcal verify --config DIR/filter.toml` checks the fitted filter.
    """
    from kalcal.api.fit import fit as run_fit
    with user_errors():
        result = run_fit(
            scenario, imu=imu, gps=gps, data=data, topic=topic, settings=settings_of(set_), config=config, free=free,
            profile=profile, gate=gate, init=init, reference=reference, sensor=sensor, imu_columns=imu_columns,
            gps_columns=gps_columns, out=out, bootstrap=bootstrap, seed=seed, threads=threads, workers=workers,
            scheduler=scheduler,
        )
    console = _common.console
    table = _common._table(
        f"kalcal fit {scenario}: {result.fixes} {result.nobs_name}",
        f"log L = {result.loglik:.6g}",
        f"{result.interval_method} intervals",
    )
    for column in ("setting", "estimate", f"{result.confidence:.0%} interval", "unit"):
        table.add_column(column, justify="right" if column == "estimate" else "left")
    for name, p in result.parameters.items():
        if p.trades_off:
            estimate, interval = "unidentified", f"trades off with {', '.join(p.trades_off)}: fitted point kept"
        elif p.held:  # a latency the fit could not resolve, held at its input
            estimate, interval = "not resolved", "input kept"
        elif not p.identified:
            estimate, interval = "unidentified", "input kept"
        else:
            estimate = f"{p.value:.4g}"
            high = "—" if p.ci_high is None else f"{p.ci_high:.4g}"
            low = "—" if p.ci_low is None else f"{p.ci_low:.4g}"
            interval = f"[0, {high}], consistent with 0" if p.at_bound else f"[{low}, {high}]"
        table.add_row(escape(name), estimate, interval, escape(p.unit))
        sample = _derived_row(result, name, p)
        if sample is not None:
            table.add_row(*sample)
    console.print(table)
    if result.bootstrap is not None:
        console.print(_bootstrap_table(result))
    if result.rejected_fixes is not None:
        rows = ", ".join(str(row) for row in result.rejected_fixes[:10]) + (", ..." if len(result.rejected_fixes) > 10 else "")
        console.print(f"gate {gate:g}: {len(result.rejected_fixes)} fix(es) rejected" + (f" (GPS rows {rows})" if rows else ""),
                      markup=False)
    if not result.converged:
        _common.error_console.print("kalcal: warning: the optimizer did not report convergence", markup=False)
    style = "green" if result.adequate else "bold red"
    console.print(f"adequate: [{style}]{'yes' if result.adequate else 'no'}[/{style}]: {escape(result.adequacy)}")
    for note in result.notes:
        console.print(f"note: {note}", markup=False, soft_wrap=True)
    _common._note_nonfinite(result.paths["fit.json"])
    _common.print_wrote(Path(out), list(result.paths.values()))
