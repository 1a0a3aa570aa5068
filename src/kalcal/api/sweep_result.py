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

    def __repr__(self) -> str:
        verdicts = ", ".join(f"{v}: {s['verdict']}" for v, s in zip(self.values, self.summaries))
        return f"SweepResult({self.key}: {verdicts})"

    def _repr_html_(self) -> str:
        return f"<div><b>kalcal sweep</b> {html.escape(self.key)}{self.table.to_html(index=False)}</div>"
