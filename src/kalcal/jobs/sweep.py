"""``kalcal sweep``: the verification run for each value of one setting, and the tuning curve."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from kalcal.errors import ConfigError
from kalcal.io.outputs import writes_outputs
from kalcal.io.results import write_json
from kalcal.jobs.verify import check_arguments, verify
from kalcal.models.config import apply_settings


@dataclass(frozen=True)
class SweepResult:
    """One row per swept value (every check's statistic, bounds and verdict), each value's run folder and
    summary as written, and the sweep's own files (``table``, ``summary``, ``figure``)."""

    key: str
    table: pd.DataFrame
    paths: dict[str, Path]
    runs: tuple[Path, ...] = ()
    summaries: tuple[dict[str, Any], ...] = ()


def split_sweep(assignments: dict[str, str]) -> tuple[str, list[str], dict[str, str]]:
    """Find the one ``key=v1,v2,...`` among ``--set`` assignments; the others stay fixed."""
    swept = {key: value for key, value in assignments.items() if "," in value}
    if len(swept) != 1:
        raise ConfigError(
            "sweep: give exactly one --set with a comma-separated list of values, e.g. "
            f"filter.accel_noise_std=0.01,0.02 (got {len(swept)})"
        )
    key, values = next(iter(swept.items()))
    values_list = [v.strip() for v in values.split(",") if v.strip()]
    if len(values_list) < 2:
        raise ConfigError(f"--set {key}={values}: a sweep needs at least two values")
    return key, values_list, {k: v for k, v in assignments.items() if k != key}


#: the files of a sweep: its table and curve, and each value's run in a folder ``key=value``
OUTPUT_NAMES = (
    "sweep.csv",
    "sweep.json",
    "sweep.png",
    *(f"*=*/{name}" for name in ("summary.json", "stats.nc", "stats_long.nc")),
)


#: the options of :func:`~kalcal.jobs.verify.verify` that :func:`~kalcal.jobs.verify.check_arguments` checks
_CHECKED = ("engine", "confidence", "long_run", "batch_size", "form")


def sweep_cells(scenario, key: str, values: list[str], n: int, **verify_options: Any) -> list:
    """The scenario of every value, each checked as :func:`~kalcal.jobs.verify.verify` would check it,
    so that a bad value is refused before the first run (and, from the CLI, before any cluster starts)."""
    cells = [apply_settings(scenario, {key: value}) for value in values]
    options = {name: verify_options[name] for name in _CHECKED if name in verify_options}
    for cell in cells:
        check_arguments(cell, n, **options)
    return cells


@writes_outputs("sweep", names=OUTPUT_NAMES)
def sweep(scenario, key: str, values: list[str], n: int, seed: int, out: str | Path, **verify_options: Any) -> SweepResult:
    """Verify ``scenario`` with ``key`` set to each value; write ``sweep.csv``, ``sweep.json``, the tuning
    curve ``sweep.png`` and one run directory ``key=value`` per value, all as one set of outputs.

    Every value uses the same seed, so the curves compare filters on the same realizations.
    """
    out = Path(out)
    cells = sweep_cells(scenario, key, values, n, **verify_options)
    rows, runs, summaries = [], [], []
    for value, cell in zip(values, cells):
        run_dir = out / f"{key}={value}"
        outcome = verify(cell, n, seed, run_dir, **verify_options)
        runs.append(run_dir)
        summaries.append(outcome.summary)
        row: dict[str, Any] = {key: float(value) if _is_number(value) else value, "verdict": outcome.summary["verdict"]}
        for check in outcome.checks:
            row[f"{check.name}_statistic"] = check.statistic
            row[f"{check.name}_lower"] = check.lower
            row[f"{check.name}_upper"] = check.upper
            row[f"{check.name}_passed"] = check.passed
        rows.append(row)
    table = pd.DataFrame(rows)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"table": out / "sweep.csv"}
    table.to_csv(paths["table"], index=False)
    paths["summary"] = write_json(
        out / "sweep.json", {"key": key, "values": values, "realizations": n, "seed": seed, "rows": rows}
    )
    from kalcal.plots.sweep import plot_sweep

    paths["figure"] = plot_sweep(table, key, out / "sweep.png")
    return SweepResult(key, table, paths, tuple(runs), tuple(summaries))


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
