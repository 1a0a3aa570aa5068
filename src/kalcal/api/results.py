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
        """The result of a :class:`kalcal.jobs.verify.Verification`."""
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
        from kalcal.jobs.verify import save_verification

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
class CalibrationResult:
    """What :func:`kalcal.calibrate` estimated, at the last fix (accel-gps) or sample (scale-bias).

    Attributes
    ----------
    scenario : str
        ``"accel-gps"`` or ``"scale-bias"``.
    bias, bias_std : float
        The sensor bias and its 1-sigma (m/s^2 for accel-gps; the log's unit for scale-bias).
    scale, scale_std : float or None
        The scale error and its 1-sigma (dimensionless): scale-bias, and accel-gps with a scale state.
    covariance : ndarray
        The final state covariance, over ``covariance_states`` (accel-gps: position, velocity, bias[,
        scale]; scale-bias: theta1, theta2).
    estimates : pandas.DataFrame
        ``estimates.csv``: one row per fix or sample, states, their 1-sigma and (accel-gps) the NIS and
        normalized innovations; made when first read (a calibration from Parquet loads pandas only then).
    diagnostics : dict
        accel-gps: the innovation diagnostics (``consistent``, ``verdict``, ...); scale-bias: the mean
        NIS, its bounds, ``consistent`` and the observability ratios.
    warnings : list of dict
        ``{"code", "message"}`` each, empty when none.
    sigma_trusted : bool
        False when the diagnostics say inconsistent or the windows are not stable: ``bias_std`` is then
        not to be used (a ``sigma-untrusted`` warning names the next step).
    settings_sigma : SettingsSigma or None
        accel-gps: the bias's sigma over the noise settings the log cannot reject, beside ``bias_std``
        (:class:`kalcal.scenarios.accel_gps.settings_sigma.SettingsSigma`: ``bias_std``, ``ratio``,
        ``at``, ...); None when not computed.
    scale_sigma_trusted : bool or None
        Whether ``scale_std`` is to be used: False where the diagnostics or windows disown the sigmas or
        (accel-gps) the scale is unobservable, its sigma then the prior's; None without a scale.
    """

    scenario: str
    bias: float
    bias_std: float
    scale: float | None
    scale_std: float | None
    covariance: np.ndarray
    covariance_states: tuple
    diagnostics: dict
    warnings: list
    calibration: Any = field(repr=False, compare=False)
    paths: dict = field(default_factory=dict)
    sigma_trusted: bool = True
    settings_sigma: Any = None
    scale_sigma_trusted: bool | None = None

    @classmethod
    def from_calibration(cls, calibration, paths: dict | None = None) -> CalibrationResult:
        """The result of a :class:`kalcal.jobs.calibrate.Calibration`."""
        s = calibration.summary
        if s["scenario"] == "scale-bias":
            scale, scale_std = s["scale_error"], s["scale_error_std"]
            covariance, states = s["theta_covariance"], s["theta_states"]
            diagnostics = {key: s[key] for key in ("mean_nis", "nis_bounds", "consistent", "observability")}
        else:
            scale, scale_std = s.get("scale"), s.get("scale_std")
            covariance, states, diagnostics = s["covariance"], s["covariance_states"], s["diagnostics"]
        return cls(
            s["scenario"],
            float(s["bias"]),
            float(s["bias_std"]),
            None if scale is None else float(scale),
            None if scale_std is None else float(scale_std),
            np.asarray(covariance, dtype=float),
            tuple(states),
            diagnostics,
            list(s["warnings"]),
            calibration,
            dict(paths or {}),
            sigma_trusted=bool(s.get("sigma_trusted", s.get("consistent", True))),
            settings_sigma=_settings_sigma(s.get("settings_sigma")),
            scale_sigma_trusted=None if scale is None else bool(s.get("scale_sigma_trusted", s.get("sigma_trusted", True))),
        )

    def to_dict(self) -> dict[str, Any]:
        """``summary.json`` as ``json.load`` reads it."""
        from kalcal.io.results import json_document

        return json_document(self.calibration.summary)

    @property
    def estimates(self) -> pd.DataFrame:
        """``estimates.csv`` as a DataFrame: made (and pandas loaded) when first read, a copy of the
        calibration's columns (editing it changes neither this result nor what :meth:`save` writes)."""
        return self.calibration.estimates

    @property
    def stability(self) -> dict | None:
        """``summary.json``'s ``stability``: the windows' estimates, the chi-square test and its verdict."""
        return self.calibration.summary.get("stability")

    def save(self, out: str | Path) -> dict[str, Path]:
        """Write ``estimates.csv``, ``summary.json`` and (accel-gps) ``calibration.png`` into ``out``, as
        ``kalcal calibrate --out`` does (one set); returns the files by name."""
        from kalcal.jobs.calibrate import save_calibration

        return save_calibration(self.calibration, out)

    @property
    def params(self) -> pd.Series:
        """The estimates: ``bias`` and, where estimated, ``scale`` (:attr:`bias`, :attr:`scale`)."""
        import pandas as pd

        return pd.Series({name: value for name, (value, _, _) in self._estimates().items()}, dtype=float, name="estimate")

    @property
    def bse(self) -> pd.Series:
        """Their 1-sigma from the final covariance (:attr:`bias_std`, :attr:`scale_std`), same index."""
        import pandas as pd

        return pd.Series({name: sigma for name, (_, sigma, _) in self._estimates().items()}, dtype=float, name="bse")

    def conf_int(self, alpha: float | None = None, level: float | None = None) -> pd.DataFrame:
        """estimate +- z sigma at ``level`` (or ``1 - alpha``; default 0.95), z the normal quantile of
        (1 + level) / 2: the filter's Gaussian posterior at the last fix or sample. Columns ``lower`` and
        ``upper``, one row per estimate (:attr:`params`' index).

        A sigma the diagnostics disown (:attr:`sigma_trusted`, :attr:`scale_sigma_trusted` False) gives an
        interval that is not to be used: a ``UserWarning`` names the estimates (and the next step is in
        :attr:`warnings`). accel-gps's :attr:`settings_sigma` (the bias's sigma over the noise settings the
        log cannot reject) is not in these intervals.
        """
        import warnings

        import pandas as pd

        from kalcal.api._display import level_of
        from kalcal.stats.distributions import normal_isf

        confidence = level_of(alpha, level, 0.95)
        z = float(normal_isf((1.0 - confidence) / 2.0))
        estimates = self._estimates()
        untrusted = [name for name, (_, _, trusted) in estimates.items() if not trusted]
        if untrusted:
            warnings.warn(f"conf_int: the sigma of {', '.join(untrusted)} is not trusted (the diagnostics or the "
                          "windows disown it): the interval is not to be used; see the result's warnings", stacklevel=2)
        rows = {name: (value - z * sigma, value + z * sigma) for name, (value, sigma, _) in estimates.items()}
        return pd.DataFrame.from_dict(rows, orient="index", columns=["lower", "upper"])

    def _estimates(self) -> dict[str, tuple[float, float, bool]]:
        """Per estimate: value, 1-sigma and whether the sigma is trusted."""
        rows = {"bias": (self.bias, self.bias_std, bool(self.sigma_trusted))}
        if self.scale is not None:
            rows["scale"] = (self.scale, np.nan if self.scale_std is None else self.scale_std, bool(self.scale_sigma_trusted))
        return rows

    def _repr_html_(self) -> str:
        from kalcal.api._display import html_facts, html_table

        ci = self._conf_int_quiet()
        rows = [[name, value, sigma, ci.loc[name, "lower"], ci.loc[name, "upper"], "yes" if trusted else "NO"]
                for name, (value, sigma, trusted) in self._estimates().items()]
        facts = html_facts(f"kalcal calibrate {self.scenario}", [
            ("consistent", self.diagnostics.get("consistent")), ("warnings", len(self.warnings)),
        ] + ([] if self.settings_sigma is None else [("bias sigma over the settings", self.settings_sigma.bias_std)]))
        table = html_table(["estimate", "value", "sigma", "[0.025", "0.975]", "sigma trusted"], rows)
        notes = "".join(f"<li>{html.escape(str(w.get('code', '')))}: {html.escape(str(w.get('message', '')))}</li>"
                        for w in self.warnings)
        return f"<div>{facts}{table}" + (f"<ul>{notes}</ul>" if notes else "") + "</div>"

    def _conf_int_quiet(self, level: float = 0.95) -> pd.DataFrame:
        """:meth:`conf_int` without its warning (the HTML table says whether each sigma is trusted)."""
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            return self.conf_int(level=level)

    def __repr__(self) -> str:
        scale = "" if self.scale is None else f", scale={self.scale:.6g} ± {self.scale_std:.3g}"
        if self.scale is not None and self.scale_sigma_trusted is False:
            scale += " (sigma NOT trusted)"
        trust = "" if self.sigma_trusted else " (sigma NOT trusted)"
        over = "" if self.settings_sigma is None else f", over the settings ± {self.settings_sigma.bias_std:.3g}"
        return (f"CalibrationResult({self.scenario}: bias={self.bias:.6g} ± {self.bias_std:.3g}{trust}{over}{scale}, "
                f"warnings={len(self.warnings)})")


def _settings_sigma(document: dict | None):
    """summary.json's ``settings_sigma`` as a SettingsSigma (None stays None)."""
    if document is None:
        return None
    from kalcal.scenarios.accel_gps.settings_sigma import SettingsSigma

    return SettingsSigma(
        bias_std=float(document["bias_std"]), conditional_bias_std=float(document["conditional_bias_std"]),
        ratio=float(document["ratio"]), factor=float(document["factor"]), confidence=float(document["confidence"]),
        free=tuple(document["free"]), at=dict(document["at"]), fitted=dict(document["fitted"]),
        filter_rejected=bool(document["filter_rejected"]),
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
        """The result of a :class:`kalcal.jobs.noise.NoiseRun`."""
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
        from kalcal.jobs.noise import save_noise

        return save_noise(self.run, out, kalibr=kalibr)["files"]

    def kalibr_yaml(self, rostopic: str = "/imu0") -> str:
        """The Kalibr ``imu.yaml`` text (see :mod:`kalcal.calibration.kalibr`)."""
        from kalcal.calibration.kalibr import kalibr_yaml

        return kalibr_yaml(self.run.identification, rostopic=rostopic)

    def _repr_html_(self) -> str:
        from kalcal.api._display import html_facts, html_table

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


@dataclass(frozen=True, repr=False, eq=False)
class SimulationResult:
    """What :func:`kalcal.simulate` drew: the logs as DataFrames (``imu``, ``gps``, ``truth`` for accel-gps;
    ``data`` for scale-bias) and, for scale-bias, ``truth`` (``truth.json``: the drawn scale error and bias)."""

    scenario: str
    logs: dict
    truth: dict | None
    simulation: Any = field(repr=False, compare=False)
    paths: dict = field(default_factory=dict)

    @classmethod
    def from_simulation(cls, simulation, paths: dict | None = None) -> SimulationResult:
        """The result of a :class:`kalcal.jobs.simulate.Simulation`."""
        truth = simulation.documents.get("truth")
        return cls(simulation.command.removeprefix("simulate "), dict(simulation.logs), truth, simulation, dict(paths or {}))

    def save(self, out: str | Path) -> dict[str, Path]:
        """Write the logs (CSV) and ``truth.json`` into ``out``, as ``kalcal simulate --out`` does (one set)."""
        from kalcal.jobs.simulate import save_simulation

        return save_simulation(self.simulation, out)

    def __repr__(self) -> str:
        return f"SimulationResult({self.scenario}: {', '.join(f'{k} ({len(v)} rows)' for k, v in self.logs.items())})"

    def _repr_html_(self) -> str:
        from kalcal.api._display import html_facts, html_table

        logs = html_table(["log", "rows", "columns"], [[name, len(frame), ", ".join(map(str, frame.columns))]
                                                       for name, frame in self.logs.items()])
        truth = "" if not self.truth else html_table(
            ["truth", "value"], [[key, value] for key, value in self.truth.items() if not isinstance(value, (dict, list))]
        )
        return f"<div>{html_facts(f'kalcal simulate {self.scenario}', [])}{logs}{truth}</div>"
