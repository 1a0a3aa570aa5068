"""What ``kalcal verify`` made: the checks, the ensemble statistics and ``summary.json``, in memory and savable."""

from __future__ import annotations

import html
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from kalcal.results._display import fmt


@dataclass(frozen=True, repr=False, eq=False)
class VerificationResult:
    """What :func:`kalcal.verify` found.

    Attributes
    ----------
    verdict : {"pass", "fail"}
        Whether every check passed (a property of ``summary``).
    checks : list of CheckResult
        Each check: ``name``, ``statistic``, ``pvalue`` (family-wise), ``lower``, ``upper``,
        ``confidence``, ``comparisons``, ``passed``, ``detail``, ``cause`` (``explained_by``,
        ``direction``) and ``parts`` (:class:`kalcal.stats.results.CheckResult`).
    statistics : xarray.Dataset
        The per-update ensemble statistics (``stats.nc``): dimensions ``time`` (s), ``state``,
        ``measurement``; a ``long_name`` on every variable, ``units`` where one unit applies.
    long_statistics : xarray.Dataset or None
        The long-run study's statistics (``stats_long.nc``), None without one.
    scenario : scenario object
        What was verified (it carries the files it was read from, which :meth:`save` keeps).
    raw_summary : dict
        ``summary.json``'s content as computed, numpy arrays and NaN as they are (``summary`` and
        :meth:`to_dict` give it as ``json.load`` reads it); its ``timing`` covers the computation
        (``total_s`` = ``wall_s`` = ``compute_s``, ``report_s`` None) until a save adds the writing.
    ensemble : EnsembleStatistics
        The per-update ensemble statistics in memory (:class:`kalcal.montecarlo.accumulators.EnsembleStatistics`),
        from which ``statistics`` and the checks were made.
    checkpoint : Path or None
        The run's checkpoint file (an input: never removed by the outputs).
    compute_s : float
        Seconds the computation took (s).
    paths : dict
        The files written (by key: summary, stats, ...) when the call was given ``out``; empty otherwise.
    self_check : SelfCheck or None
        The bench's self-check, apart from the verdict: the ensemble's mean error, variances, E[e xhat^T]
        and mean innovations against the exact analysis of the same filter and truth (``statistic``, ``bound``, ``pvalue``, ``agrees``,
        ``confidence``, ``parts``, ``detail``; ``agrees`` None and a ``reason`` where no exact analysis
        exists) (:class:`kalcal.stats.self_check.SelfCheck`).
    power : list of dict or None
        The power each check and part had at the run's N under the truth (``summary.json``'s ``power``:
        ``{"name", "part", "power_low", "power_high", "detectable", "detection_n"}``), from the exact
        analysis of the same problem; None where none exists (``summary["power_reason"]`` says why).
    effect_sizes, cramer_rao, power_by_simulation : typed or None
        A nonlinear model's run-level effect sizes, Cramér–Rao bound per state and power by simulation
        (:mod:`kalcal.results.effects`), built from ``summary.json``'s sections of those names; None where
        the run has none.
    """

    scenario: Any = field(repr=False)
    raw_summary: dict[str, Any] = field(repr=False)
    ensemble: Any = field(repr=False)
    checks: list = field(repr=False)
    statistics: Any = field(repr=False)
    long_statistics: Any = field(repr=False)
    checkpoint: Path | None = None
    compute_s: float = 0.0
    self_check: Any = None
    paths: dict = field(default_factory=dict)

    @property
    def verdict(self) -> str:
        """"pass" or "fail": whether every check passed (``summary.json``'s ``verdict``)."""
        return self.raw_summary["verdict"]

    @property
    def power(self) -> list[dict[str, Any]] | None:
        """``summary.json``'s ``power``: each check's power at the run's N under the truth, None without an
        exact analysis (``summary["power_reason"]`` says why)."""
        return self.raw_summary.get("power")

    @property
    def effect_sizes(self):
        """The run's effect sizes over every update, typed (:class:`kalcal.results.effects.RunEffectSizes`,
        from ``summary.json``'s ``effect_sizes``); None where the run has none (a linear scenario's)."""
        from kalcal.results.effects import RunEffectSizes

        d = self.raw_summary.get("effect_sizes")
        return None if d is None else RunEffectSizes.from_summary(d)

    @property
    def cramer_rao(self):
        """The posterior Cramér–Rao bound per state against the ensemble's MSE, typed
        (:class:`kalcal.results.effects.CramerRaoSummary`, from ``summary.json``'s ``cramer_rao``); None
        where the run has none."""
        from kalcal.results.effects import CramerRaoSummary

        d = self.raw_summary.get("cramer_rao")
        return None if d is None else CramerRaoSummary.from_summary(d)

    @property
    def power_by_simulation(self):
        """Each check's rejection rate under named alternatives by repeated runs, typed
        (:class:`kalcal.results.effects.PowerBySimulation`, from ``summary.json``'s
        ``power_by_simulation``); None where none was run (``checks.power_runs`` = 0)."""
        from kalcal.results.effects import PowerBySimulation

        d = self.raw_summary.get("power_by_simulation")
        return None if d is None else PowerBySimulation.from_summary(d)

    @property
    def summary(self) -> dict[str, Any]:
        """:meth:`to_dict`."""
        return self.to_dict()

    def to_dict(self) -> dict[str, Any]:
        """``summary.json`` as ``json.load`` reads it (NaN as None, ``schema_version``, ``nonfinite``); its
        ``timing`` is the computation's until the result is saved (then the file adds the writing)."""
        from kalcal.io.results import json_document

        return json_document(self.raw_summary)

    def save(self, out: str | Path, *, report: bool = False, realization: int = 0) -> dict[str, Path]:
        """Write ``summary.json``, ``stats.nc`` (``stats_long.nc``) and, with ``report``, ``report.html``
        and ``figures/`` into ``out``, as ``kalcal verify --out`` does (one set: whole or not at all,
        docs/outputs.md); returns the files by key."""
        from kalcal.api.verification import save_verification

        return save_verification(
            self, out, report=report, realization=realization, checkpoint=self.checkpoint, scenario=self.scenario
        ).paths

    def report(self, path: str | Path = "report.html", *, realization: int = 0) -> Path:
        """Draw the self-contained HTML page (realization ``realization`` in the single-run figures) at ``path``."""
        path = Path(path)
        with tempfile.TemporaryDirectory(prefix="kalcal-report-") as folder:
            paths = self.save(Path(folder) / "run", report=True, realization=realization)
            path.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(paths["report"], path)
        return path

    def __repr__(self) -> str:
        s = self.raw_summary
        failed = [c.name for c in self.checks if not c.passed]
        return (
            f"VerificationResult(verdict={self.verdict!r}, scenario={s['scenario']!r}, realizations={s['realizations']}, "
            f"checks={len(self.checks)}" + (f", failed={failed}" if failed else "") + ")"
        )

    def _repr_html_(self) -> str:
        s = self.raw_summary
        rows = "".join(
            "<tr>"
            f"<td>{html.escape(c.name)}</td><td>{fmt(c.statistic)}</td><td>{fmt(c.lower)}</td><td>{fmt(c.upper)}</td>"
            f"<td>{fmt(c.pvalue)}</td><td style='color:{'green' if c.passed else 'red'}'>{'pass' if c.passed else 'FAIL'}</td>"
            "</tr>"
            for c in self.checks
        )
        return (
            f"<div><b>kalcal verify {html.escape(str(s['scenario']))}</b>: {s['realizations']:,} realizations "
            f"({html.escape(s['engine'])}), confidence {s['confidence']:g}, verdict <b>{html.escape(self.verdict.upper())}</b>"
            "<table><thead><tr><th>check</th><th>statistic</th><th>lower</th><th>upper</th><th>p-value</th><th>result</th>"
            f"</tr></thead><tbody>{rows}</tbody></table></div>"
        )
