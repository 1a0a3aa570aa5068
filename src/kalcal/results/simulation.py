"""The result of ``kalcal.simulate``: one realization's logs, made by the scenario, saved as CSV and JSON."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path


@dataclass(frozen=True, repr=False, eq=False)
class SimulationResult:
    """What :func:`kalcal.simulate` drew: the logs as DataFrames (``imu``, ``gps``, ``truth`` for accel-gps;
    ``data`` for scale-bias), for scale-bias ``truth`` (``truth.json``: the drawn scale error and bias), and
    the files a save writes (``output_names``). Made by the scenario's ``simulate(seed)``."""

    scenario: str
    logs: dict
    truth: dict | None
    output_names: tuple = field(repr=False)
    paths: dict = field(default_factory=dict)

    @property
    def command(self) -> str:
        """``"simulate <scenario>"``."""
        return f"simulate {self.scenario}"

    def with_paths(self, paths: dict) -> SimulationResult:
        """The same result, with where its files were written."""
        return dataclasses.replace(self, paths=dict(paths))

    def to_dict(self) -> dict:
        """What the simulation wrote beside its logs, as ``json.load`` reads it: ``scenario``, each log's
        ``rows`` and ``columns`` by name, and ``truth`` (``truth.json``'s content, None where there is none)."""
        from kalcal.io.results import json_document

        return json_document({
            "scenario": self.scenario,
            "logs": {name: {"rows": len(frame), "columns": [str(c) for c in frame.columns]} for name, frame in self.logs.items()},
            "truth": self.truth,
        })

    def save(self, out: str | Path) -> dict[str, Path]:
        """Write each log as ``NAME.csv`` and ``truth`` (where there is one) as ``truth.json`` into ``out``, as
        ``kalcal simulate --out`` does (one set); returns the files by name (``imu``, ``truth``, ...)."""
        from kalcal.io.outputs import writes_outputs

        @writes_outputs(self.command, names=self.output_names)
        def write(result: SimulationResult, out: Path) -> dict[str, Path]:
            from kalcal.io.results import write_json

            out = Path(out)
            out.mkdir(parents=True, exist_ok=True)
            paths: dict[str, Path] = {}
            for name, frame in result.logs.items():
                paths[name] = out / f"{name}.csv"
                frame.to_csv(paths[name], index=False)
            if result.truth is not None:
                paths["truth"] = write_json(out / "truth.json", result.truth)
            return paths

        return write(self, out)

    def __repr__(self) -> str:
        return f"SimulationResult({self.scenario}: {', '.join(f'{k} ({len(v)} rows)' for k, v in self.logs.items())})"

    def _repr_html_(self) -> str:
        from kalcal.results._display import html_facts, html_table

        logs = html_table(["log", "rows", "columns"], [[name, len(frame), ", ".join(map(str, frame.columns))]
                                                       for name, frame in self.logs.items()])
        truth = "" if not self.truth else html_table(
            ["truth", "value"], [[key, value] for key, value in self.truth.items() if not isinstance(value, (dict, list))]
        )
        return f"<div>{html_facts(f'kalcal simulate {self.scenario}', [])}{logs}{truth}</div>"
