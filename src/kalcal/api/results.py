"""The result objects of ``kalcal.verify``, ``kalcal.calibrate`` and ``kalcal.noise``: frozen, in memory, savable."""

from __future__ import annotations

import html
import shutil
import tempfile
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np


if TYPE_CHECKING:  # annotations only: a verification result needs no pandas
    import pandas as pd


def _fmt(value: Any) -> str:
    if value is None:
        return "—"
    if isinstance(value, (float, np.floating)):
        return f"{float(value):.4g}"
    return str(value)


@dataclass(frozen=True, repr=False, eq=False)
class VerificationResult:
    """What :func:`kalcal.verify` found.

    Attributes
    ----------
    verdict : {"pass", "fail"}
        Whether every check passed.
    checks : list of CheckResult
        Each check: ``name``, ``statistic``, ``pvalue`` (family-wise), ``lower``, ``upper``,
        ``confidence``, ``comparisons``, ``passed``, ``detail``, ``cause`` (``explained_by``,
        ``direction``) and ``parts`` (:class:`kalcal.stats.results.CheckResult`).
    statistics : xarray.Dataset
        The per-update ensemble statistics (``stats.nc``): dimensions ``time`` (s), ``state``,
        ``measurement``; a ``long_name`` on every variable, ``units`` where one unit applies.
    long_statistics : xarray.Dataset or None
        The long-run study's statistics (``stats_long.nc``), None without one.
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
    """

    verdict: str
    checks: list
    run: Any = field(repr=False, compare=False)
    paths: dict = field(default_factory=dict)
    self_check: Any = None
    power: Any = None

    @classmethod
    def from_run(cls, run, paths: dict | None = None) -> VerificationResult:
        """The result of a :class:`kalcal.api.verification.Verification`."""
        return cls(
            run.summary["verdict"],
            list(run.checks),
            run,
            dict(paths or {}),
            run.self_check,
            run.summary.get("power"),
        )

    @cached_property
    def statistics(self):
        """``stats.nc`` as an ``xarray.Dataset``."""
        return self.run.dataset

    @cached_property
    def long_statistics(self):
        """``stats_long.nc`` as an ``xarray.Dataset``, None without a long run."""
        return self.run.long_dataset

    @property
    def summary(self) -> dict[str, Any]:
        """:meth:`to_dict`."""
        return self.to_dict()

    def to_dict(self) -> dict[str, Any]:
        """``summary.json`` as ``json.load`` reads it (NaN as None, ``schema_version``, ``nonfinite``); its
        ``timing`` is the computation's until the result is saved (then the file adds the writing)."""
        from kalcal.io.results import json_document

        return json_document(self.run.summary)

    def save(self, out: str | Path, *, report: bool = False, realization: int = 0) -> dict[str, Path]:
        """Write ``summary.json``, ``stats.nc`` (``stats_long.nc``) and, with ``report``, ``report.html``
        and ``figures/`` into ``out``, as ``kalcal verify --out`` does (one set: whole or not at all,
        docs/outputs.md); returns the files by key."""
        from kalcal.api.verification import save_verification

        saved = save_verification(
            self.run, out, report=report, realization=realization, checkpoint=self.run.checkpoint, scenario=self.run.scenario
        )
        return saved.paths

    def report(self, path: str | Path = "report.html", *, realization: int = 0) -> Path:
        """Draw the self-contained HTML page (realization ``realization`` in the single-run figures) at ``path``."""
        path = Path(path)
        with tempfile.TemporaryDirectory(prefix="kalcal-report-") as folder:
            paths = self.save(Path(folder) / "run", report=True, realization=realization)
            path.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(paths["report"], path)
        return path

    def __repr__(self) -> str:
        s = self.run.summary
        failed = [c.name for c in self.checks if not c.passed]
        return (
            f"VerificationResult(verdict={self.verdict!r}, scenario={s['scenario']!r}, realizations={s['realizations']}, "
            f"checks={len(self.checks)}" + (f", failed={failed}" if failed else "") + ")"
        )

    def _repr_html_(self) -> str:
        s = self.run.summary
        rows = "".join(
            "<tr>"
            f"<td>{html.escape(c.name)}</td><td>{_fmt(c.statistic)}</td><td>{_fmt(c.lower)}</td><td>{_fmt(c.upper)}</td>"
            f"<td>{_fmt(c.pvalue)}</td><td style='color:{'green' if c.passed else 'red'}'>{'pass' if c.passed else 'FAIL'}</td>"
            "</tr>"
            for c in self.checks
        )
        return (
            f"<div><b>kalcal verify {html.escape(str(s['scenario']))}</b>: {s['realizations']:,} realizations "
            f"({html.escape(s['engine'])}), confidence {s['confidence']:g}, verdict <b>{html.escape(self.verdict.upper())}</b>"
            "<table><thead><tr><th>check</th><th>statistic</th><th>lower</th><th>upper</th><th>p-value</th><th>result</th>"
            f"</tr></thead><tbody>{rows}</tbody></table></div>"
        )


@dataclass(frozen=True, repr=False, eq=False)
class NoiseResult:
    """What :func:`kalcal.noise` identified from a static accelerometer log.

    Attributes
    ----------
    velocity_random_walk, bias_instability, rate_random_walk, accel_noise_std, bias_walk_std : NoiseParameter
        N (m/s/sqrt(s)), B (m/s^2), K (m/s^2/sqrt(s)) and the per-sample values N sqrt(rate) and
        K sqrt(dt) (m/s^2), each with ``value`` (None where not identified), ``ci_low``, ``ci_high``,
        ``upper_bound`` and ``note`` (:class:`kalcal.calibration.noise.NoiseParameter`).
    rate : float
        The log's median sample rate (Hz).
    filter : dict
        The ``[filter]`` settings of ``filter.toml``: the rate-free densities accel_noise_density (N,
        m/s^2/sqrt(Hz)) and bias_walk_density (K, m/s^3/sqrt(Hz)) where identified.
    kalibr : dict
        The Kalibr ``imu.yaml`` values (continuous-time densities; see :mod:`kalcal.calibration.kalibr`).
    allan : pandas.DataFrame
        ``allan.csv``: tau [s], adev and its bounds [m/s^2], edf, noise type.
    warnings : list of dict
        ``{"code", "message"}`` each (a log that does not look static), empty when none.
    axes : dict
        A three-axis log's (a bag's or ULog's accelerometer) ``{"x": NoiseIdentification, "y": ..., "z":
        ...}``, empty for one column. The parameters above are then the selected axis's (``axis=``), None
        without one, and ``kalibr`` holds the largest densities over the axes.
    """

    velocity_random_walk: Any
    bias_instability: Any
    rate_random_walk: Any
    accel_noise_std: Any
    bias_walk_std: Any
    rate: float
    filter: dict
    kalibr: dict
    allan: pd.DataFrame
    warnings: list
    run: Any = field(repr=False, compare=False)
    paths: dict = field(default_factory=dict)
    axes: dict = field(default_factory=dict, repr=False)

    @classmethod
    def from_run(cls, run, paths: dict | None = None) -> NoiseResult:
        """The result of a :class:`kalcal.calibration.noise_run.NoiseRun`."""
        from kalcal.calibration.kalibr import axes_kalibr_values, kalibr_values

        r = run.identification
        rostopic = getattr(run, "topic", None) or "/imu0"
        axes = dict(getattr(run, "axes", {}) or {})
        names = ("velocity_random_walk", "bias_instability", "rate_random_walk", "accel_noise_std", "bias_walk_std")
        return cls(
            *(None if r is None else getattr(r, name) for name in names),
            float(run.summary["rate"]["value"]),
            dict(run.summary["filter"]),
            axes_kalibr_values(axes, rostopic) if axes else kalibr_values(r, rostopic),
            run.allan,
            list(run.summary["warnings"]),
            run,
            dict(paths or {}),
            axes,
        )

    def to_dict(self) -> dict[str, Any]:
        """``summary.json`` as ``json.load`` reads it, but for ``files`` (which only a save knows)."""
        from kalcal.io.results import json_document

        return json_document(self.run.summary)

    def save(self, out: str | Path, *, kalibr: bool = True) -> dict[str, str]:
        """Write ``summary.json``, ``allan.csv``, ``allan.png``, ``filter.toml`` and (unless ``kalibr`` is
        False) the Kalibr ``imu.yaml`` into ``out``, as ``kalcal noise --out`` does (one set); returns the
        files by key (summary, allan, plot, filter, kalibr)."""
        from kalcal.calibration.noise_run import save_noise

        return save_noise(self.run, out, kalibr=kalibr)["files"]

    def kalibr_yaml(self, rostopic: str = "/imu0") -> str:
        """The Kalibr ``imu.yaml`` text (see :mod:`kalcal.calibration.kalibr`)."""
        from kalcal.calibration.kalibr import kalibr_yaml

        return kalibr_yaml(self.run.identification, rostopic=rostopic)

    def _repr_html_(self) -> str:
        from kalcal.results._display import html_facts, html_table

        names = ("velocity_random_walk", "bias_instability", "rate_random_walk", "accel_noise_std", "bias_walk_std")
        rows = []
        for name in names:
            p = getattr(self, name)
            rows.append([name, p.value, p.low, p.high, p.upper_bound, p.unit, p.note])
        confidence = self.velocity_random_walk.confidence
        facts = html_facts("kalcal noise", [("rate, Hz", self.rate), ("confidence", confidence), ("warnings", len(self.warnings))])
        table = html_table(["parameter", "value", "lower", "upper", "upper bound", "unit", "note"], rows)
        notes = "".join(f"<li>{html.escape(str(w.get('code', '')))}: {html.escape(str(w.get('message', '')))}</li>"
                        for w in self.warnings)
        return f"<div>{facts}{table}" + (f"<ul>{notes}</ul>" if notes else "") + "</div>"

    def __repr__(self) -> str:
        def show(p) -> str:
            return "not identified" if p.value is None else f"{p.value:.4g} {p.unit}"

        return (
            f"NoiseResult(N={show(self.velocity_random_walk)}, B={show(self.bias_instability)}, "
            f"K={show(self.rate_random_walk)}, rate={self.rate:.6g} Hz)"
        )
