"""``kalcal sweep``: a verification per value of one setting and the tuning curve, through :func:`kalcal.api.sweep.sweep`."""

from pathlib import Path
from typing import Annotated, Optional

import typer

from kalcal.cli import _common
from kalcal.cli._common import SCENARIO_NAMES, ConfigOpt, SetOpt, TopicOpt, user_errors


def sweep(
    scenario: Annotated[str, typer.Argument(help=f"Scenario: {', '.join(SCENARIO_NAMES)}.")] = "accel-gps",
    n: Annotated[int, typer.Option("-n", "--realizations", help="Monte Carlo realizations per value.")] = 100_000,
    seed: Annotated[int, typer.Option("--seed", help="Root seed, the same for every value.")] = 0,
    out: Annotated[Path, typer.Option("--out", help="Directory for sweep.csv, sweep.png and one run per value.")] = Path(
        "kalcal-sweep"
    ),
    engine: Annotated[str, typer.Option("--engine", help="exact or sampled.")] = "exact",
    threads: Annotated[Optional[int], typer.Option("--threads", help="Local threads (default: all cores).")] = None,
    workers: Annotated[Optional[int], typer.Option("--workers", help="Local Dask cluster of this many processes.")] = None,
    scheduler: Annotated[Optional[str], typer.Option("--scheduler", help="Existing Dask cluster address.")] = None,
    data: Annotated[
        Optional[Path],
        typer.Option(
            "--data",
            help="A log for a model file's [data] table: every value verified over it, as verify --data (the same "
            "log for every value, its record in each run).",
        ),
    ] = None,
    topic: TopicOpt = None,
    set_: SetOpt = None,
    config: ConfigOpt = None,
) -> None:
    """Verify once per value of one setting (--set key=v1,v2,...) and draw the tuning curve.

    A model file is swept over one number of it (filter.v, filter.w.2, filter.phi.1.2, truth.KEY likewise,
    filter.steps_per_update, model.updates): each value's run is its verify with --set key=value.
    """
    from kalcal.api.sweep import sweep as run_sweep
    from kalcal.api.sweep import sweep_settings

    with user_errors():
        key, values, fixed = sweep_settings(set_ or ())
        result = run_sweep(
            scenario, key, values, n, seed, out, fixed, config=config, engine=engine, threads=threads,
            workers=workers, scheduler=scheduler, data=data, topic=topic,
        )
    table = _common._table(f"kalcal sweep {scenario}: {key}", f"{n:,} realizations per value")
    table.add_column(key, justify="right")
    checks = [c[: -len("_passed")] for c in result.table.columns if c.endswith("_passed")]
    for check in checks:
        table.add_column(check, justify="right")
    for _, row in result.table.iterrows():
        cells = [f"{row[f'{c}_statistic']:.4g}" + ("" if row[f"{c}_passed"] else " [red]x[/red]") for c in checks]
        table.add_row(str(row[key]), *cells)
    _common.console.print(table)
    _common._note_nonfinite(result.paths["summary"], *(run / "summary.json" for run in result.runs))
    written = [result.paths[key] for key in ("summary", "table", "figure")] + sorted(result.runs)
    _common.print_wrote(Path(out), written)
