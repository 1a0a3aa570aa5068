"""The result of ``kalcal.calibrate``: the estimates at the last fix or sample, their files, their intervals.

:class:`CalibrationResult` holds what every scenario's calibration has (the bias, its sigma, the final
covariance, the diagnostics' verdict, the stability test, the warnings and ``estimates.csv``'s columns);
each scenario subclasses it beside its calibration, with the fields only it has
(:class:`kalcal.scenarios.accel_gps.calibrate.AccelGpsCalibrationResult`,
:class:`kalcal.scenarios.scale_bias.job.ScaleBiasCalibrationResult`). Each is the object the calibration
made; ``summary.json`` is generated from its fields (:attr:`~CalibrationResult.summary`, ``to_dict()``)
and ``save(out)`` writes it, last.
"""

from __future__ import annotations

import dataclasses
import html
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

import numpy as np

if TYPE_CHECKING:
    import pandas as pd

    from kalcal.calibration.plausibility import CalibrationWarning


class Diagnostics(Protocol):
    """What every calibration's innovation diagnostics have: whether the filter is consistent with the log,
    the verdict in words and ``summary.json``'s form of them."""

    consistent: bool

    @property
    def verdict(self) -> str: ...

    def to_dict(self) -> dict[str, Any]: ...


@dataclass(frozen=True)
class CalibrateOptions:
    """The options of one calibration (``kalcal calibrate``'s, named once here): each scenario takes the
    ones it has and refuses, in one line, one it has not that was given (:meth:`refuse_unless`).

    Attributes
    ----------
    imu_columns, gps_columns : str or None
        Log-column maps ``"role=column,..."`` (accel-gps).
    init : {"first-fix", "prior"}
        Where the filter starts (accel-gps).
    max_imu_gap : float
        A step longer than this many sample periods is a gap (accel-gps).
    on_gap : {"continue", "stop"}
    form : {"joseph", "standard", "sqrt"}
        The filter's update form (accel-gps).
    smooth : bool
        Add the RTS-smoothed states (accel-gps).
    gate : float or None
        The innovation gate's confidence (accel-gps).
    settings_sigma : bool
        Also the bias's sigma over the noise settings (accel-gps).
    reference, sensor : str
        The log's columns (scale-bias).
    prior : {"diffuse", "settings"} or None
        scale-bias's prior of theta.
    windows : int
        Windows of the stability test (1: none).
    poses : str, path or None
        A JSON of static poses' sample ranges, ``{"x_p": {"start": i, "end": j}, ...}`` (imu-3axis).
    fit_options : tuple of str
        The command line's other options (``--config FILE``, ``--set k=v``), repeated in a next step's
        ``kalcal fit`` command.
    """

    imu_columns: str | None = None
    gps_columns: str | None = None
    init: str = "first-fix"
    max_imu_gap: float = 5.0
    on_gap: str = "continue"
    form: str = "joseph"
    smooth: bool = False
    gate: float | None = None
    settings_sigma: bool = True
    reference: str = "reference"
    sensor: str = "sensor"
    prior: str | None = None
    windows: int = 2
    poses: str | Path | None = None
    fit_options: tuple[str, ...] = ()

    def given(self, *names: str) -> list[str]:
        """Of ``names``, the options set to other than their defaults."""
        defaults = CalibrateOptions()
        return [name for name in names if getattr(self, name) != getattr(defaults, name)]

    def refuse_unless(self, scenario: str, taken: tuple[str, ...]) -> None:
        """Refuse, in one line naming the first, an option set to other than its default that the scenario
        ``scenario`` does not take (``taken``: its class's ``CALIBRATE_OPTIONS``); the message names the
        scenarios that take it, asked of the registry (:func:`kalcal.scenarios.calibrate_option_takers`)."""
        from kalcal.errors import KalcalError

        names = [field.name for field in dataclasses.fields(self) if field.name not in (*taken, "fit_options")]
        other = self.given(*names)
        if other:
            from kalcal.scenarios import calibrate_option_takers

            option = "--" + other[0].replace("_", "-")
            takers = calibrate_option_takers(other[0])
            who = f" ({' and '.join(takers)} only)" if takers else ""
            raise KalcalError(f"{option}: not available for {scenario}{who}")


@dataclass(frozen=True, repr=False, eq=False)
class CalibrationResult:
    """What :func:`kalcal.calibrate` estimated: at the last fix (accel-gps), sample (scale-bias) or row (a
    model file), or from the static poses (imu-3axis); each scenario's subclass adds its own fields.

    Attributes
    ----------
    scenario : str
        The scenario's ``NAME``: ``"accel-gps"``, ``"scale-bias"``, ``"imu-3axis"``, or ``"custom"`` for a
        model file (its model's own name is the subclass's ``name``, summary.json's ``model``). A model
        written as code has no calibration (refused in one line).
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
    diagnostics : Diagnostics
        The innovation diagnostics as the calibration computed them, each with ``consistent``, ``verdict``
        and ``to_dict()`` (``summary.json``'s form): accel-gps's
        :class:`~kalcal.calibration.diagnostics.InnovationDiagnostics` (the mean NIS and Ljung-Box tests),
        scale-bias's :class:`~kalcal.scenarios.scale_bias.job.ScaleBiasDiagnostics` (the mean NIS, its
        bounds and the observability).
    warnings : tuple of CalibrationWarning
        Each with ``code``, ``message`` and, where the message names one, ``next_step``
        (:class:`~kalcal.calibration.plausibility.CalibrationWarning`); ``to_dict()`` is ``summary.json``'s
        ``{"code", "message"}``. Empty when none.
    columns : dict of str to ndarray
        ``estimates.csv``'s columns, each (K,) for the K fixes or samples.
    time : float
        s, the last fix's or sample's time: the time the estimates refer to.
    units : dict of str to str
        The unit of each quantity of :meth:`table` (and ``time``), as ``summary.json``'s ``units``.
    stability_test : Stability
        The windows' stability test (:class:`kalcal.calibration.stability.Stability`);
        :attr:`stability` is its ``summary.json`` form.
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
    diagnostics: Diagnostics
    warnings: tuple[CalibrationWarning, ...]
    columns: dict = field(repr=False, compare=False)
    time: float
    units: dict
    stability_test: Any
    paths: dict = field(default_factory=dict)
    sigma_trusted: bool = True
    settings_sigma: Any = None
    scale_sigma_trusted: bool | None = None

    #: the files a calibration writes (a scenario's subclass adds its own)
    OUTPUT_NAMES: ClassVar[tuple[str, ...]] = ("estimates.csv", "summary.json")

    @property
    def command(self) -> str:
        """The command whose outputs these are (``"calibrate <scenario>"``)."""
        return f"calibrate {self.scenario}"

    def with_paths(self, paths: dict) -> CalibrationResult:
        """The same result, with where its files were written."""
        return dataclasses.replace(self, paths=dict(paths))

    @cached_property
    def summary(self) -> dict[str, Any]:
        """``summary.json``'s content, generated from the fields when first read (arrays as arrays:
        :meth:`to_dict` is the document as ``json.load`` reads it)."""
        return self._summary()

    def _summary(self) -> dict[str, Any]:
        """``summary.json`` from the fields: each scenario's subclass writes its own keys, in its order."""
        raise NotImplementedError(f"{type(self).__name__}: no summary.json for this result")

    def to_dict(self) -> dict[str, Any]:
        """``summary.json`` as ``json.load`` reads it."""
        from kalcal.io.results import json_document

        return json_document(self.summary)

    @cached_property
    def estimates(self) -> pd.DataFrame:
        """``estimates.csv`` as a DataFrame: made (and pandas loaded) when first read, a copy of the
        calibration's columns (editing it changes neither this result nor what :meth:`save` writes)."""
        import pandas as pd

        return pd.DataFrame(self.columns, copy=True)

    @property
    def stability(self) -> dict:
        """``summary.json``'s ``stability``: the windows' estimates, the chi-square test and its verdict
        (:attr:`stability_test` as a document)."""
        return self.stability_test.as_dict()

    def save(self, out: str | Path) -> dict[str, Path]:
        """Write ``estimates.csv``, ``summary.json`` and the scenario's own files (:attr:`OUTPUT_NAMES`) into
        ``out``, as ``kalcal calibrate --out`` does (one set, :mod:`kalcal.io.outputs`); returns the files by
        name. The logs it was read from are never removed."""
        from kalcal.io.outputs import writes_outputs

        @writes_outputs(self.command, names=self.OUTPUT_NAMES)
        def write(result: CalibrationResult, out: Path) -> dict[str, Path]:
            from kalcal.io.results import write_csv, write_json

            out = Path(out)
            paths = {"estimates.csv": write_csv(out / "estimates.csv", result.columns),
                     "summary.json": write_json(out / "summary.json", result.summary)}
            return {**paths, **result._save_more(out)}

        return write(self, out)

    def _save_more(self, out: Path) -> dict[str, Path]:
        """The scenario's own files beside estimates.csv and summary.json (a subclass draws them)."""
        return {}

    def table(self) -> list[tuple[str, float, float, bool, str]]:
        """The CLI's table: (quantity, estimate, 1-sigma, whether the sigma is trusted, unit) per row."""
        return [(name, value, sigma, trusted, self.units.get(name, ""))
                for name, (value, sigma, trusted) in self._estimates().items()]

    def title(self) -> str:
        """The CLI table's title (what the estimates rest on) and caption (when)."""
        return f"kalcal calibrate {self.scenario}", f"t = {self.time:g} s"

    def extra_rows(self) -> list[tuple[str, str, str, str]]:
        """Rows the CLI adds below the table, each (quantity, estimate, 1-sigma, unit) as text; none here."""
        return []

    def lines(self) -> list[tuple[str, bool | None]]:
        """The CLI's lines after the table, each (text, verdict): True green, False red, None plain."""
        return []

    def diagnostics_line(self) -> tuple[str, bool] | None:
        """The innovation diagnostics' verdict in words and whether it is consistent, for the CLI; None where
        the calibration has none to state."""
        return None

    def strict_failed(self) -> bool:
        """Whether ``--strict`` exits with status 1: a warning raised."""
        return bool(self.warnings)

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

        from kalcal.results._display import level_of
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
        from kalcal.results._display import html_facts, html_table

        ci = self._conf_int_quiet()
        rows = [[name, value, sigma, ci.loc[name, "lower"], ci.loc[name, "upper"], "yes" if trusted else "NO"]
                for name, (value, sigma, trusted) in self._estimates().items()]
        facts = html_facts(f"kalcal calibrate {self.scenario}", [
            ("consistent", self.diagnostics.consistent), ("warnings", len(self.warnings)),
        ] + ([] if self.settings_sigma is None else [("bias sigma over the settings", self.settings_sigma.bias_std)]))
        table = html_table(["estimate", "value", "sigma", "[0.025", "0.975]", "sigma trusted"], rows)
        notes = "".join(f"<li>{html.escape(w.code)}: {html.escape(w.message)}</li>" for w in self.warnings)
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
