"""``kalcal analyze``: the exact covariance analysis, through :func:`kalcal.analyze`, printed as a table."""

import sys
from pathlib import Path
from typing import Annotated, Optional

import typer

from kalcal.cli import _common
from kalcal.cli._common import ConfigOpt, TopicOpt, SetOpt, settings_of, user_errors


def analyze(
    scenario: Annotated[
        str, typer.Argument(help="Scenario: accel-gps, or a model file (.toml, docs/custom-models.md).")
    ] = "accel-gps",
    n: Annotated[int, typer.Option("-n", "--realizations", help="Realizations the checks' power is computed for.")] = 300_000,
    out: Annotated[Path, typer.Option("--out", help="Directory for analysis.json, analysis.nc and figures/.")] = Path(
        "kalcal-analysis"
    ),
    form: Annotated[str, typer.Option("--form", help="The filter's update form: joseph (default), standard or sqrt.")] = "joseph",
    data: Annotated[
        Optional[Path],
        typer.Option("--data", help="A log for a model file's [data] table: the gains from its rows, the same in every realization."),
    ] = None,
    set_: SetOpt = None,
    config: ConfigOpt = None,
    topic: TopicOpt = None,
) -> None:
    """Exact covariance analysis, no sampling: the true error covariance of the filter's gains and its budget by source."""
    import shlex

    from rich import box

    from kalcal.api.analyze import analyze as run_analyze
    from kalcal.api.analyze import state_rows

    with user_errors():
        result = run_analyze(
            scenario, settings_of(set_), n, config=config, form=form, out=out, command=shlex.join(["kalcal", *sys.argv[1:]]), data=data, topic=topic
        )
    final = result.final
    table = _common._table(
        f"kalcal analyze {result.document['scenario']}",
        f"at {final['time']:g} s",
        f"in {1000 * result.document['timing']['analysis_s']:.0f} ms",
        box=box.SIMPLE_HEAD,
        pad_edge=False,
    )
    for name, justify in (("state", "left"), ("filter σ", "right"), ("true σ", "right"), ("mean e", "right"),
                          ("top source", "left"), ("share", "right")):  # fmt: skip
        table.add_column(name, justify=justify, no_wrap=True)
    for row in state_rows(result):
        state = f"{row['state']} ({row['unit']})" if row["unit"] else row["state"]
        table.add_row(
            state, f"{row['filter_sigma']:.3g}", f"{row['true_sigma']:.3g}", f"{row['mean_error']:.3g}",
            row["top_source"], f"{100 * row['top_share']:.0f}%",
        )  # fmt: skip
    _common.console.print(table)
    if result.document.get("not_checked"):  # a diffuse filter's diffuse period: the analysis starts after it
        _common.console.print(f"not checked: {result.document['not_checked']}", markup=False, soft_wrap=True)
    for note in result.document.get("notes") or ():  # a model file's known inputs: cancelled or carried
        _common.console.print(f"note: {note}", markup=False, soft_wrap=True)
    from kalcal.stats.power import N_CAP, power_line
    from kalcal.stats.sensitivity import sensitivity_text

    equal = result.truth_equals_filter
    _common.console.print(power_line(result.power, n, equal=equal), markup=False, soft_wrap=True)
    if result.sensitivity is not None:
        found = ", ".join(sensitivity_text(row) for row in result.sensitivity)
        why = "a correct filter" if equal else f"no check detects the truth up to N = {N_CAP:,}"
        _common.console.print(f"detected at N = {n:,} with power 0.99 ({why}): {found}", markup=False, soft_wrap=True)
    _common._note_nonfinite(result.paths["summary"])
    _common.print_wrote(Path(out), [result.paths[key] for key in ("summary", "dataset")] + [Path(out) / "figures"])
