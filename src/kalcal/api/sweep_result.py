"""The result of ``kalcal.sweep``: the table, each value's run summary and where the files are."""

from __future__ import annotations

import html
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

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

    @classmethod
    def from_sweep(cls, sweep, values: list[str]) -> SweepResult:
        """The result of :func:`kalcal.jobs.sweep.sweep` (its paths final)."""
        from kalcal.io.results import json_document

        return cls(
            sweep.key, list(values), sweep.table, [json_document(summary) for summary in sweep.summaries],
            [Path(run) for run in sweep.runs], dict(sweep.paths),
        )

    def save(self, out: str | Path) -> dict[str, Path]:
        """Write the sweep's files into ``out`` as ``kalcal sweep --out`` does (one set: ``sweep.csv``,
        ``sweep.json``, ``sweep.png`` and each value's run folder ``key=value`` as its own set inside it),
        copied from the folder the sweep wrote (a sweep always writes, :func:`kalcal.sweep`); returns the
        sweep's own files by key (table, summary, figure), as :attr:`paths`."""
        import shutil

        from kalcal.errors import KalcalError
        from kalcal.io.manifest import MANIFEST, read_manifest
        from kalcal.io.outputs import run_outputs
        from kalcal.jobs.sweep import OUTPUT_NAMES
        from kalcal.jobs.verify import OUTPUT_NAMES as RUN_NAMES

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
