"""``kalcal verify``: the Monte Carlo verification, through :func:`kalcal.verify`, printed as a table."""

import sys
from pathlib import Path
from typing import Annotated, Optional

import typer

from kalcal.cli import _common
from kalcal.cli._common import SCENARIO_NAMES, ConfigOpt, TopicOpt, SetOpt, settings_of, user_errors


def verify(
    scenario: Annotated[
        str, typer.Argument(help=f"Scenario: {', '.join(SCENARIO_NAMES)}, or a model file (.toml, docs/custom-models.md).")
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
    data: Annotated[
        Optional[Path],
        typer.Option("--data", help="A log for a model file's [data] table: the gains from its rows, the same in every realization."),
    ] = None,
    set_: SetOpt = None,
    config: ConfigOpt = None,
    topic: TopicOpt = None,
) -> None:
    """Verify the filter with a Monte Carlo: mean error, covariance, orthogonality, whiteness, NIS."""
    import shlex

    from kalcal.api.verify import verify as run_verify
    with user_errors():
        bar, update = _common._progress_bar(f"{scenario} x {n:,}")
        with bar:
            result = run_verify(
                scenario,
                n,
                seed,
                settings_of(set_),
                config=config,
                engine=engine,
                confidence=confidence,
                threads=threads,
                workers=workers,
                scheduler=scheduler,
                batch_size=batch_size,
                checkpoint=checkpoint,
                long_run=long_run,
                form=form,
                progress=update or False,
                out=out,
                report=not no_report,
                realization=realization,
                command=shlex.join(["kalcal", *sys.argv[1:]]),
                notes=_common.print_note,
                data=data, topic=topic,
            )
    summary = result.raw_summary
    _common._print_checks(summary)
    from kalcal.reporting.text import scope_statement

    _common.console.print(scope_statement(summary), markup=False, soft_wrap=True)
    from kalcal.stats.power import power_line
    from kalcal.stats.self_check import self_check_line

    equal = bool(summary.get("power_truth_equals_filter"))
    _common.console.print(power_line(summary["power"], n, summary["power_reason"], equal), markup=False, soft_wrap=True)
    _common.console.print(self_check_line(summary.get("self_check")), markup=False, soft_wrap=True)
    pair = summary["residual_correlation"]
    if pair is not None:  # only runs that have the source report's pair of updates
        rows = ", ".join(
            "[" + ", ".join(f"{m:.3g} ± {se:.2g}" for m, se in zip(row, errors)) + "]"
            for row, errors in zip(pair["matrix"], pair["standard_error"])
        )
        _common.console.print(
            f"E[r_k r_j^T] at t_k = {pair['k_time']:g} s, t_j = {pair['j_time']:g} s (± standard error): [{rows}]",
            markup=False,
            soft_wrap=True,
        )
    _common._note_nonfinite(result.paths["summary"])
    order = ("summary", "stats", "stats_long", "report", "figures")
    written = [result.paths[key] for key in order if key in result.paths]
    written += [path for key, path in result.paths.items() if key not in order]
    _common.print_wrote(Path(out), written)
    if strict and summary["verdict"] != "pass":
        raise typer.Exit(1)
