"""A fit's files written as one set, and the options of ``kalcal fit`` named once (:class:`FitOptions`).

The files are fit.json, filter.toml, fit.png and a scenario's own, such as Kalibr's imu.yaml.

Each scenario's ``fit(logs, options)`` reads its logs and fits (``kalcal.scenarios.<name>``), and returns
the :class:`~kalcal.fitting.result.FitResult` it made, completed by :func:`for_command` with what its
files need; what is common to every fit, its files, is here."""

from __future__ import annotations

import dataclasses
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
#: ... and with ``--bootstrap B``, each setting's bootstrap distribution with its likelihood interval on it
BOOTSTRAP_NAME = "fit-bootstrap.png"


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
    bootstrap : int
        B, the parametric bootstrap's replicates (:mod:`kalcal.fitting.bootstrap`); 0: none.
    seed : int
        The bootstrap's root seed (the Monte Carlo engine's SeedSequence scheme).
    threads : int or None
        The bootstrap's local threads (default: the CPUs this process may use).
    client : dask.distributed.Client or None
        Run the bootstrap's replicates as Dask tasks instead.
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
    bootstrap: int = 0
    seed: int = 0
    threads: int | None = None
    client: Any = None


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


def for_command(
    result: FitResult,
    command: str,
    inputs: dict[str, str],
    free: list[str],
    filter_text: str,
    kalibr_text: str | None = None,
    linear: tuple[str, ...] = (),
) -> FitResult:
    """``result`` as the command ``command`` (``"fit accel-gps"``) made it: with the logs it read
    (``inputs``, fit.json's ``inputs``), the settings it fitted (``free``), filter.toml's text
    (:func:`filter_toml`), imu.yaml's (where the scenario's noise has one) and the settings drawn on a
    linear axis in fit.png: the fields that its ``to_dict()`` (fit.json) and ``save(out)`` use."""
    return dataclasses.replace(result, command=command, inputs=dict(inputs), free=list(free), filter_text=filter_text,
                               kalibr_text=kalibr_text, linear=tuple(linear))


def output_names(result: FitResult) -> tuple[str, ...]:
    """The files ``result`` writes: :data:`OUTPUT_NAMES` (filter.toml under the result's ``filter_name``), and
    :data:`KALIBR_NAME` where it has imu.yaml's text."""
    names = tuple(result.filter_name if name == "filter.toml" else name for name in OUTPUT_NAMES)
    names = names if result.kalibr_text is None else (*names, KALIBR_NAME)
    return names if result.bootstrap is None else (*names, BOOTSTRAP_NAME)


def save_fit(result: FitResult, out: str | Path) -> dict[str, Path]:
    """Write ``fit.json``, ``filter.toml``, ``fit.png``, for accel-gps ``imu.yaml`` and with a bootstrap
    ``fit-bootstrap.png`` into ``out`` as one set (:mod:`kalcal.io.outputs`); returns the files by name (where they are once the set is in place)."""
    out = Path(out)
    names = output_names(result)
    with run_outputs(out, result.command, names=names, protect=inputs_of(result)) as staging:
        staging.mkdir(parents=True, exist_ok=True)
        from kalcal.fitting.mle import drop_of
        from kalcal.plots.fit import plot_fit

        document = result.to_dict()
        write_json(staging / "fit.json", document)
        (staging / result.filter_name).write_text(result.filter_text)
        if result.kalibr_text is not None:
            (staging / KALIBR_NAME).write_text(result.kalibr_text)
        plot_fit(result.curves, document["parameters"], staging / "fit.png",
                 method=result.interval_method, drop=drop_of(result.confidence), linear=tuple(result.linear))
        if result.bootstrap is not None:
            from kalcal.plots.fit import plot_bootstrap

            plot_bootstrap(result, staging / BOOTSTRAP_NAME)
    return {name: out / name for name in names}
