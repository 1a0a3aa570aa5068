"""``kalcal.analyze``: the exact covariance analysis of a fixed-gain filter, returned as an AnalysisResult."""

from __future__ import annotations

import html
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

from kalcal.io.outputs import writes_outputs

#: the files ``kalcal analyze`` writes (glob patterns relative to --out)
OUTPUT_NAMES = ("analysis.json", "analysis.nc", "figures/sigma.png", "figures/budget.png")


@dataclass(frozen=True, repr=False)
class AnalysisResult:
    """What :func:`kalcal.analyze` computed, exactly, for the filter's gains against the truth.

    Attributes
    ----------
    final : dict
        After the last update: ``time`` (s), ``states``, ``units``, ``filter_covariance`` (the filter's
        P), ``error_covariance`` (P_true, centered) and ``mean_error``; matrices as row-major lists.
    budget : list of dict
        One term of P_true per independent source: ``source`` ("prior:position", "process:accel",
        "measurement:velocity", ...), ``kind``, ``final`` (d x d; the terms sum to
        ``final["error_covariance"]``) and ``variance_fraction`` (each state's share).
    power : list of dict
        The power each check (``part`` None) and each of its parts had at ``n`` realizations under the
        truth, at 99% confidence: ``{"name", "part", "power_low", "power_high", "detectable",
        "detection_n"}`` (docs/analysis.md, :mod:`kalcal.stats.power`).
    dataset : xarray.Dataset
        Every per-update quantity (``analysis.nc``): dimensions ``update`` (coordinate ``time``, s),
        ``state``, ``state_col``, ``measurement``, ``measurement_col``, ``update_col``, ``source``.
    parts : xarray.Dataset
        The same Dataset.
    paths : dict
        The files written (by key) when the call was given ``out``; empty otherwise.
    sensitivity : list of dict or None
        For a correct filter (no check detects the truth at any N), per noise setting of the truth:
        ``{"setting", "increase", "decrease"}``, the smallest relative error (a fraction) that ``n``
        realizations detect with power 0.99 (:mod:`kalcal.stats.sensitivity`); None otherwise.
    """
    final: dict
    budget: list
    power: Any
    parts: Any = field(repr=False, compare=False)
    document: dict = field(repr=False, compare=False)
    analysis: Any = field(repr=False, compare=False)
    paths: dict = field(default_factory=dict)
    sensitivity: Any = None

    @cached_property
    def dataset(self):
        """``analysis.nc`` as an ``xarray.Dataset`` (see the class's docstring)."""
        return self.parts

    @property
    def truth_equals_filter(self) -> bool:
        """Whether the truth equals the filter in everything the checks see (then no check can detect it at
        any N; :func:`kalcal.stats.power.truth_equals_filter`)."""
        from kalcal.stats.power import truth_equals_filter

        return truth_equals_filter(self.analysis)

    def to_dict(self) -> dict[str, Any]:
        """``analysis.json`` as ``json.load`` reads it (``schema_version`` first, ``nonfinite`` last)."""
        from kalcal.io.results import json_document

        return json_document(self.document)

    def save(self, out: str | Path) -> dict[str, Path]:
        """Write ``analysis.json``, ``analysis.nc`` and ``figures/`` into ``out``, as ``kalcal analyze --out``
        does (one set: whole or not at all, docs/outputs.md); returns the files by key."""
        return save_analysis(self, out)

    def __repr__(self) -> str:
        f = self.final
        return f"AnalysisResult(scenario={self.document['scenario']!r}, time={f['time']:g} s, states={f['states']}, sources={len(self.budget)})"

    def _repr_html_(self) -> str:
        rows = "".join(
            f"<tr><td>{html.escape(row['state'])}</td><td>{row['filter_sigma']:.4g}</td><td>{row['true_sigma']:.4g}</td>"
            f"<td>{row['mean_error']:.4g}</td><td>{html.escape(row['top_source'])}</td></tr>"
            for row in state_rows(self)
        )
        return (
            f"<div><b>kalcal analyze {html.escape(str(self.document['scenario']))}</b> at {self.final['time']:g} s"
            "<table><thead><tr><th>state</th><th>filter σ</th><th>true σ</th><th>mean error</th><th>top source</th>"
            f"</tr></thead><tbody>{rows}</tbody></table></div>"
        )


def state_rows(result: AnalysisResult) -> list[dict[str, Any]]:
    """Per state after the last update: filter sigma, true sigma, mean error, unit and the source with the
    largest share of the true variance (and that share)."""
    f = result.final
    rows = []
    for i, (name, unit) in enumerate(zip(f["states"], f["units"])):
        shares = [b["variance_fraction"][i] for b in result.budget]
        top = max(range(len(shares)), key=shares.__getitem__) if shares else None
        rows.append({
            "state": name, "unit": unit,
            "filter_sigma": max(f["filter_covariance"][i][i], 0.0) ** 0.5,
            "true_sigma": max(f["error_covariance"][i][i], 0.0) ** 0.5,
            "mean_error": f["mean_error"][i],
            "top_source": "" if top is None else result.budget[top]["source"],
            "top_share": 0.0 if top is None else shares[top],
        })  # fmt: skip
    return rows


def analyze(
    scenario: Any = "accel-gps",
    settings: Mapping[str, Any] | None = None,
    n: int = 300_000,
    *,
    config: str | Path | None = None,
    form: str = "joseph",
    out: str | Path | None = None,
    command: str = "",
    data: str | Path | None = None,
    topic: str | None = None,
) -> AnalysisResult:
    """The exact covariance analysis of the filter's gains against the truth: no sampling.

    At every update: the mean error, the centered true error covariance P_true, E[e xhat^T],
    E[r_k r_j^T] for every pair, the mean NEES and NIS under the truth, and the error budget (P_true
    split into one term per independent source of the truth). Fixed-gain filters only: accel-gps and
    model files.

    Parameters
    ----------
    scenario : str, path, Model or scenario
        ``"accel-gps"``, a model file (``.toml``), a :class:`kalcal.Model`, or a built scenario.
    settings : dict, optional
        ``{"section.key": value}``, the keys of ``--set`` (``{"truth.accel_noise_std": 0.04}``).
    n : int
        The realizations the checks' power (and, for a correct filter, the sensitivity) is computed for.
    config : path, optional
        A TOML file of settings (``--config``).
    form : {"joseph", "standard", "sqrt"}
        The filter's covariance update (the gains follow from it).
    out : path, optional
        Also write ``analysis.json``, ``analysis.nc`` and ``figures/`` there, as ``kalcal analyze --out``.
    command : str
        What ``analysis.json`` records as the command.
    data : path, optional
        A log for a model file with a ``[data]`` table (``--data LOG``): the analysis of the gains that the
        log's rows give (per-update H_k, V_k, Phi_k, Q_k), as ``kalcal.verify(..., data=)`` runs them.
    topic : str, optional
        ``data`` a ROS bag or ULog: the topic the file's [data] table reads (``--topic``).

    Raises
    ------
    KalcalError
        Bad input, or scale-bias (its gains depend on the noisy readings: no exact analysis exists).
    """
    from kalcal.api._scenario import resolve, with_data
    from kalcal.errors import KalcalError
    from kalcal.core.steps import check_form

    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise KalcalError(f"-n: expected a positive number of realizations, got {n!r}")
    check_form(form, "--form")
    model = with_data(resolve(scenario, settings, config, models=True), data, "analyze", topic)
    if out is None:
        return _compute(model, n, form, command)
    from dataclasses import replace

    from kalcal.io.outputs import inputs_of, run_outputs

    # the folder is checked before the analysis runs, and its files are put in place as one set
    with run_outputs(out, "analyze", names=OUTPUT_NAMES, protect=inputs_of(model)) as staging:
        result = _compute(model, n, form, command)
        saved = save_analysis(result, staging)
    return replace(result, paths={key: Path(out) / Path(path).relative_to(staging) for key, path in saved.items()})


def _compute(model, n: int, form: str, command: str) -> AnalysisResult:
    from kalcal.analysis.dataset import analysis_dataset, budget_summary, final_summary
    from kalcal.analysis.fixed_gain import analyze_scenario
    from kalcal.api.verification import left_out
    from kalcal.models.config import section_values

    start = time.perf_counter()
    analysis = analyze_scenario(model, form)
    elapsed = time.perf_counter() - start
    final, budget = final_summary(analysis), budget_summary(analysis)
    power, sensitivity, power_s = _power(model, analysis, n, form)
    document = {
        "scenario": analysis.info.scenario,
        "settings": section_values(model),
        "form": form,
        "realizations": n,
        **left_out(analysis.info),
        "final": final,
        "budget": budget,
        "power": power,
        "sensitivity": sensitivity,
        "timing": {"analysis_s": elapsed, "power_s": power_s},
        "command": command,
    }
    dataset = analysis_dataset(analysis, {"form": form})
    return AnalysisResult(final, budget, power, dataset, document, analysis, sensitivity=sensitivity)


def _power(model, analysis, n: int, form: str) -> tuple[list, list | None, float]:
    """The checks' power at ``n``, the sensitivity where no check detects the truth, and the seconds both took."""
    from kalcal.stats.suite import power_rows
    from kalcal.stats.sensitivity import sensitivity

    start = time.perf_counter()
    power = power_rows(analysis, n)
    correct = not any(row["detectable"] for row in power)
    found = sensitivity(model, n, form=form) if correct else None
    return power, found, time.perf_counter() - start


@writes_outputs("analyze", names=OUTPUT_NAMES)
def save_analysis(result: AnalysisResult, out: str | Path) -> dict[str, Path]:
    """``analysis.json``, ``analysis.nc`` and the two figures, written into ``out`` as one set."""
    from kalcal.io.results import write_json
    from kalcal.io.statistics import write_statistics
    from kalcal.plots.analysis import plot_analysis

    out = Path(out)
    paths = {
        "summary": write_json(out / "analysis.json", result.document),
        "dataset": write_statistics(out / "analysis.nc", result.parts),
    }
    return {**paths, **plot_analysis(result.parts, out / "figures")}
