"""``kalcal.sweep``: a verification per value of one setting, written with the tuning curve.

The sweep's result (:class:`SweepResult`) is the object the run made: its table, each value's summary as
written and folder, and the sweep's own files.
"""

from __future__ import annotations

import html
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from kalcal.api.verification import check_arguments, verify
from kalcal.errors import ConfigError
from kalcal.io.outputs import writes_outputs
from kalcal.io.results import json_document, write_json
from kalcal.models.config import apply_settings
from kalcal.api.model import flat_settings


@dataclass(frozen=True, repr=False, eq=False)
class SweepResult:
    """What :func:`kalcal.sweep` found, one verification per value of ``key``.

    Attributes
    ----------
    key : str
        The swept setting (``"filter.accel_noise_std"``).
    values : list of str
        Its values, in the order run.
    table : pandas.DataFrame
        ``sweep.csv``: one row per value with every check's statistic, bounds and verdict.
    summaries : list of dict
        Each value's ``summary.json`` as ``json.load`` reads it (as written), in the order of ``values``.
    runs : list of Path
        Each value's run folder (``out/key=value``), in the order of ``values``.
    paths : dict
        The sweep's own files: ``table`` (sweep.csv), ``summary`` (sweep.json), ``figure`` (sweep.png).
    """

    key: str
    values: list
    table: pd.DataFrame
    summaries: list
    runs: list
    paths: dict
    realizations: int | None = None  #: per value
    seed: int | None = None

    def to_dict(self) -> dict:
        """``sweep.json`` as ``json.load`` reads it: ``key``, ``values``, ``realizations``, ``seed`` and ``rows``
        (``sweep.csv``'s rows, each check's statistic, bounds and verdict per value)."""
        return json_document({"key": self.key, "values": list(self.values), "realizations": self.realizations,
                              "seed": self.seed, "rows": self.table.to_dict("records")})

    def save(self, out: str | Path) -> dict[str, Path]:
        """Write the sweep's files into ``out`` as ``kalcal sweep --out`` does (one set: ``sweep.csv``,
        ``sweep.json``, ``sweep.png`` and each value's run folder ``key=value`` as its own set inside it),
        copied from the folder the sweep wrote (a sweep always writes, :func:`kalcal.sweep`); returns the
        sweep's own files by key (table, summary, figure), as :attr:`paths`."""
        import shutil

        from kalcal.errors import KalcalError
        from kalcal.io.manifest import MANIFEST, read_manifest
        from kalcal.io.outputs import run_outputs
        from kalcal.api.verification import OUTPUT_NAMES as RUN_NAMES

        out = Path(out)
        if any(Path(path).parent.resolve() == out.resolve() for path in self.paths.values()):
            return dict(self.paths)  # the set is there already: saving it again changes nothing
        runs = []
        for run in self.runs:
            manifest = read_manifest(run)
            if manifest is None or not manifest.complete:
                raise KalcalError(f"save: {run}: the run's folder is missing or incomplete; run the sweep again")
            runs.append((Path(run), [name for name in manifest.files if Path(name).name != MANIFEST]))
        with run_outputs(out, "sweep", names=OUTPUT_NAMES) as staging:
            for path in self.paths.values():
                shutil.copy2(path, staging / Path(path).name)
            for run, files in runs:
                with run_outputs(staging / run.name, "verify", names=RUN_NAMES) as inner:
                    for name in files:
                        (inner / name).parent.mkdir(parents=True, exist_ok=True)
                        shutil.copy2(run / name, inner / name)
        return {key: out / Path(path).name for key, path in self.paths.items()}

    def __repr__(self) -> str:
        verdicts = ", ".join(f"{v}: {s['verdict']}" for v, s in zip(self.values, self.summaries))
        return f"SweepResult({self.key}: {verdicts})"

    def _repr_html_(self) -> str:
        # pandas escapes the cells (to_html's escape=True)
        return f"<div><b>kalcal sweep</b> {html.escape(self.key)}{self.table.to_html(index=False, escape=True)}</div>"


def sweep(
    scenario: str = "accel-gps",
    key: str = "",
    values: Sequence[Any] = (),
    n: int = 100_000,
    seed: int = 0,
    out: str | Path | None = None,
    settings: Mapping[str, Any] | None = None,
    *,
    config: str | Path | None = None,
    engine: str = "exact",
    threads: int | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    client=None,
    data: str | Path | None = None,
    topic: str | None = None,
):
    """Verify ``scenario`` with ``key`` (``"filter.accel_noise_std"``) set to each of ``values``, all with
    the same seed; writes (``out`` is required) ``out/sweep.csv``, ``sweep.json``, ``sweep.png`` and one run folder per value
    (as ``kalcal sweep``). Returns a :class:`kalcal.SweepResult` (``key``, ``values``, ``table``: one row
    per value with every check's statistic, bounds and verdict, ``summaries`` and ``runs``: each value's
    summary.json and folder, ``paths``: the sweep's own files).

    A model file (a ``.toml`` path, a :class:`kalcal.Model` or a scenario :func:`kalcal.load_model` read)
    is swept over one number of it (:func:`model_file_cells`): each value's run is the file's ``verify``
    with ``--set key=value`` (and ``--data data``, the same log for every value, its record in each run)."""
    from kalcal.api._scenario import resolve, with_data
    from kalcal.errors import KalcalError

    if out is None:
        raise KalcalError("out: required (the folder for sweep.csv, sweep.png and one run per value; a sweep always writes)")
    values = [str(value) for value in values]
    if not key or len(values) < 2:
        raise KalcalError(f"sweep: give a setting and at least two values (got {key!r} with {len(values)})")
    if threads is not None and threads < 1:
        raise KalcalError(f"--threads: expected a positive number, got {threads}")
    from kalcal.montecarlo.distributed import dask_client

    options = dict(engine=engine, workers=threads, long_run=0)
    if _is_model_file(scenario):
        model, cells = model_file_cells(scenario, key, values, settings, config, data, topic, n, engine=engine)
    else:
        if data is not None or topic is not None:  # a built-in over a log: its own one-line refusal
            with_data(resolve(scenario, None, config, models=True), data, "sweep", topic)
        # an unknown name: the list of those with a sweep
        model = resolve(scenario, settings, config, command="sweep")
        cells = sweep_cells(model, key, values, n, engine=engine, long_run=0)  # every value checked before any cluster
    if client is None and (workers is not None or scheduler is not None):
        with dask_client(workers, scheduler) as client:
            return run_sweep(model, key, values, n, seed, out, cells=cells, client=client, **options)
    return run_sweep(model, key, values, n, seed, out, cells=cells, client=client, **options)


def sweep_settings(assignments: Sequence[str]) -> tuple[str, list[str], dict[str, str]]:
    """``--set`` assignments (``key=v1,v2,...`` among them) as the swept key, its values and the fixed settings."""
    from kalcal.models.settings import parse_assignments

    return split_sweep(parse_assignments(assignments))


def split_sweep(assignments: dict[str, str]) -> tuple[str, list[str], dict[str, str]]:
    """Find the one ``key=v1,v2,...`` among ``--set`` assignments; the others stay fixed."""
    # a comma inside brackets is a TOML array's (a model file's matrix, filter.w=[[1, 0], [0, 1]]): held fixed
    swept = {key: value for key, value in assignments.items() if len(_top_level(value)) > 1}
    if len(swept) != 1:
        raise ConfigError(
            "sweep: give exactly one --set with a comma-separated list of values, e.g. "
            f"filter.accel_noise_std=0.01,0.02 (got {len(swept)})"
        )
    key, values = next(iter(swept.items()))
    values_list = [v.strip() for v in _top_level(values) if v.strip()]
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


#: the options of :func:`~kalcal.api.verification.verify` that :func:`~kalcal.api.verification.check_arguments` checks
_CHECKED = ("engine", "confidence", "long_run", "batch_size", "form")


def _top_level(value: str) -> list[str]:
    """``value`` split at its commas outside brackets (``0.1,[[1, 2]]`` -> ``["0.1", "[[1, 2]]"]``)."""
    parts, depth, start = [], 0, 0
    for i, char in enumerate(value):
        depth += {"[": 1, "]": -1}.get(char, 0)
        if char == "," and depth == 0:
            parts.append(value[start:i])
            start = i + 1
    return [*parts, value[start:]]


def _is_model_file(scenario: Any) -> bool:
    """A model file (``.toml``), a :class:`~kalcal.api.model.Model` or a scenario read from a model file."""
    from kalcal.api.model import Model
    from kalcal.scenarios import is_model_file, model_file_fields

    if isinstance(scenario, Model) or (isinstance(scenario, (str, Path)) and is_model_file(str(scenario))):
        return True
    return model_file_fields(scenario) is not None


def model_file_cells(
    scenario: Any,
    key: str,
    values: list[str],
    settings: Mapping[str, Any] | None,
    config: str | Path | None,
    data: str | Path | None,
    topic: str | None,
    n: int,
    **verify_options: Any,
) -> tuple[Any, list]:
    """The model file's scenario with the fixed settings, and its scenario of every value: the file with ``settings`` and ``--set key=value`` (over
    the log ``data`` where one is given, read and fingerprinted once: every value runs over the same bytes),
    each checked as ``verify`` checks it and its problem built (what only the gains show: a diffuse period
    that never ends, a singular P), so that a bad value is refused, named, before the first run.

    Refused in one line (the scenario's ``sweep_refusal``, :mod:`kalcal.scenarios.model_file.entries`): a key that names a
    matrix of more than one number (the keys of its numbers are named), a key that is no number of the
    model, and the timing keys over a log; and whatever ``verify`` refuses of the file (a diffuse filter without a [truth] m0).
    """
    from kalcal.api._scenario import resolve, with_data
    from kalcal.capabilities import require
    from kalcal.errors import KalcalError

    fixed = {k: v for k, v in flat_settings(settings).items() if k != key}
    base = with_data(resolve(scenario, fixed, config, models=True), data, "verify", topic)
    why = base.sweep_refusal(key)
    if why:
        raise KalcalError(f"sweep: {key}: {why}")
    require(base, "sweep")  # what verify refuses of the file, in its own words
    if data is not None:
        data = base.log  # the log's record (path, digest, topic) taken once: every value runs over the same bytes
    options = {name: verify_options[name] for name in _CHECKED if name in verify_options}
    cells = []
    for value in values:
        cell = with_data(resolve(scenario, {**fixed, key: value}, config, models=True), data, "verify")
        check_arguments(cell, n, **options)
        try:  # its problem built once here (the gains: cheap), so that what only it finds is refused now too
            cell.problem()
        except KalcalError as error:  # a diffuse period that never ends, a singular P: named with the value
            raise KalcalError(f"sweep: {key}={value}: {error}") from None
        cells.append(cell)
    return base, cells


def sweep_cells(scenario, key: str, values: list[str], n: int, **verify_options: Any) -> list:
    """The scenario of every value, each checked as :func:`~kalcal.api.verification.verify` would check it,
    so that a bad value is refused before the first run (and, from the CLI, before any cluster starts)."""
    cells = [apply_settings(scenario, {key: value}) for value in values]
    options = {name: verify_options[name] for name in _CHECKED if name in verify_options}
    for cell in cells:
        check_arguments(cell, n, **options)
    return cells


@writes_outputs("sweep", names=OUTPUT_NAMES)
def run_sweep(
    scenario, key: str, values: list[str], n: int, seed: int, out: str | Path, *, cells: list | None = None,
    **verify_options: Any,
) -> SweepResult:
    """Verify ``scenario`` with ``key`` set to each value (``cells``: those scenarios, built and checked
    already, :func:`sweep_cells`, :func:`model_file_cells`; the files ``scenario`` was read from are
    protected); write ``sweep.csv``, ``sweep.json``, the tuning curve ``sweep.png`` and one
    run directory ``key=value`` per value, all as one set of outputs.

    Every value uses the same seed, so the curves compare filters on the same realizations.
    """
    out = Path(out)
    cells = sweep_cells(scenario, key, values, n, **verify_options) if cells is None else cells
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
    result = SweepResult(key, list(values), table, [json_document(summary) for summary in summaries], runs, paths,
                         realizations=n, seed=seed)
    paths["summary"] = write_json(out / "sweep.json", result.to_dict())  # the document its to_dict() gives
    from kalcal.plots.sweep import plot_sweep

    paths["figure"] = plot_sweep(table, key, out / "sweep.png")
    return result


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
