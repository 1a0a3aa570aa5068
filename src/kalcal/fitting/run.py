"""A fit's files made in memory and written as one set, and the options of ``kalcal fit`` named once (:class:`FitOptions`).

The files are fit.json, filter.toml, fit.png and a scenario's own, such as Kalibr's imu.yaml.

Each scenario's ``fit(logs, options)`` reads its logs and fits (``kalcal.scenarios.<name>``); what is
common to every fit, its files, is here."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from kalcal.fitting.result import FitResult
from kalcal.io.outputs import inputs_of, run_outputs
from kalcal.io.results import write_json

#: the files of one fit
OUTPUT_NAMES = ("fit.json", "filter.toml", "fit.png")
#: ... and where a fit gives the Kalibr noise file too, as ``kalcal noise`` writes it
KALIBR_NAME = "imu.yaml"


@dataclass(frozen=True)
class FitOptions:
    """The options of one fit (``kalcal fit``'s, named once here); each scenario takes its own.

    Attributes
    ----------
    free : list of str or None
        The settings fitted (None: the scenario's default).
    profile : bool
        Intervals from the profile likelihood instead of the observed information.
    confidence : float
        Of the intervals.
    imu_columns, gps_columns, init, gate
        accel-gps: as ``calibrate``'s.
    reference, sensor : str
        scale-bias: the log's columns.
    """

    free: list[str] | None = None
    profile: bool = False
    confidence: float = 0.95
    imu_columns: str | None = None
    gps_columns: str | None = None
    init: str = "first-fix"
    gate: float | None = None
    reference: str = "reference"
    sensor: str = "sensor"


@dataclass(frozen=True)
class FitRun:
    """A fit computed in memory, nothing written yet.

    Attributes
    ----------
    command : str
        ``"fit accel-gps"`` or ``"fit scale-bias"``.
    result : FitResult
    document : dict
        fit.json's content.
    filter_text : str
        filter.toml, loadable by ``--config`` of calibrate and verify.
    kalibr_text : str or None
        imu.yaml, the fitted noise densities in Kalibr's form (:func:`kalcal.calibration.kalibr.fit_kalibr_yaml`),
        where the scenario's noise has one.
    linear : tuple of str
        The fitted settings drawn on a linear axis in fit.png (the others on a log axis).
    """

    command: str
    result: FitResult
    document: dict[str, Any]
    filter_text: str
    kalibr_text: str | None = None
    linear: tuple[str, ...] = ()

    @property
    def output_names(self) -> tuple[str, ...]:
        """The files it writes."""
        return OUTPUT_NAMES if self.kalibr_text is None else (*OUTPUT_NAMES, KALIBR_NAME)


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    return repr(float(value))


def filter_toml(result: FitResult, header: list[str]) -> str:
    """filter.toml: ``header`` as comments, then each section; a fitted key carries its interval as a
    comment above it, an unidentified one its note (the input value kept; a ridge's members: the fitted point)."""
    lines = [f"# {line}" for line in header]
    lines += [f"# {note}" for note in result.notes]
    used = set()
    for section, values in result.settings.items():
        lines += ["", f"[{section}]"]
        for key, value in values.items():
            # a comment keyed "section.key" belongs to that key, a bare key to [filter]'s
            for name in (f"{section}.{key}", key if section == "filter" else None):
                if name in result.comments:
                    lines.append(f"# {result.comments[name]}")
                    used.add(name)
            lines.append(f"{key} = {_toml_value(value)}")
    extra = [text for key, text in result.comments.items() if key not in used]
    if extra:
        lines += [""] + [f"# {text}" for text in extra]
    return "\n".join(lines) + "\n"


def document(result: FitResult, command: str, sources: dict[str, str], free: list[str]) -> dict[str, Any]:
    return {**result.to_dict(), "command": command, "inputs": sources, "free": free, "settings": result.settings}


def save_fit(run: FitRun, out: str | Path) -> dict[str, Path]:
    """Write ``fit.json``, ``filter.toml``, ``fit.png`` and, for accel-gps, ``imu.yaml`` into ``out`` as one
    set (:mod:`kalcal.io.outputs`); returns the files by name (where they are once the set is in place)."""
    out = Path(out)
    names = run.output_names
    with run_outputs(out, run.command, names=names, protect=inputs_of(run)) as staging:
        staging.mkdir(parents=True, exist_ok=True)
        from kalcal.fitting.mle import drop_of
        from kalcal.plots.fit import plot_fit

        write_json(staging / "fit.json", run.document)
        (staging / "filter.toml").write_text(run.filter_text)
        if run.kalibr_text is not None:
            (staging / KALIBR_NAME).write_text(run.kalibr_text)
        plot_fit(run.result.curves, run.document["parameters"], staging / "fit.png",
                 method=run.result.interval_method, drop=drop_of(run.result.confidence), linear=tuple(run.linear))
    return {name: out / name for name in names}
