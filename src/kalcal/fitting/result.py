"""What a maximum-likelihood fit of noise settings found: each parameter, the fit's quality, fit.json's layout."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # annotations only: a fit needs pandas only when its tables are read
    import pandas as pd

#: how the 95% intervals were computed
INTERVAL_METHODS = ("observed-information", "profile")


@dataclass(frozen=True)
class FitParameter:
    """One fitted setting.

    Attributes
    ----------
    name : str
        The setting, as ``--set`` spells it (``"filter.accel_noise_std"``).
    value : float or None
        The maximum-likelihood estimate in the setting's unit; None when the log cannot identify it.
    ci_low, ci_high : float or None
        The interval at ``FitResult.confidence`` (0 as ``ci_low`` for an estimate consistent with 0; None
        where the likelihood does not fall far enough within the search range).
    unit : str
    start : float
        Where the search started (the input setting, or a small positive floor for a setting that was 0).
    identified : bool
        False when the log-likelihood is flat: it falls by less than the interval's drop (1.92 for 95%)
        over the whole search range on both sides of the estimate; when the parameter trades off with
        others along a ridge (``trades_off``); and for a latency whose log-likelihood is too rough at the
        sample scale for an interval (:mod:`kalcal.scenarios.accel_gps.latency_scan`).
    at_bound : bool
        True when the log-likelihood at the search range's lower end is within the drop of the maximum:
        the estimate is consistent with 0 and ``ci_high`` is an upper limit.
    note : str
        A plain sentence for the user when one is due ("" otherwise).
    trades_off : tuple of str
        The parameters this one trades off with along a ridge of log L (unidentified: only their
        combination is); () otherwise. Not in fit.json's entry (the ``note`` names them).
    held : bool
        True for a latency the fit could not resolve (:mod:`kalcal.scenarios.accel_gps.latency_scan`): unidentified,
        held at its input while the other settings were refitted. Not in fit.json's entry (the ``note``
        says it).
    scale : {"log", "linear"}
        The scale the search ran on: u = ln(value) (a positive setting), or u = value (a time offset).
    se : float or None
        The standard error of u from the observed information (dimensionless for ``scale="log"``, the
        setting's unit for ``"linear"``) where ``ci_low``/``ci_high`` are its Wald interval
        u_hat +- z se mapped back; None where the interval is a likelihood-ratio one (profile, one-sided,
        consistent with 0, a latency's grid) or there is none. Not in fit.json's entry.
    """

    name: str
    value: float | None
    ci_low: float | None
    ci_high: float | None
    unit: str
    start: float
    identified: bool = True
    at_bound: bool = False
    note: str = ""
    trades_off: tuple[str, ...] = ()
    held: bool = False
    scale: str = "log"
    se: float | None = None

    def as_dict(self) -> dict[str, Any]:
        return {
            "value": self.value,
            "ci_low": self.ci_low,
            "ci_high": self.ci_high,
            "unit": self.unit,
            "start": self.start,
            "identified": self.identified,
            "at_bound": self.at_bound,
            "note": self.note,
        }


@dataclass(frozen=True, repr=False)
class FitResult:
    """A fit of one log's noise settings by maximum likelihood.

    Read as a statsmodels fit is: :attr:`params` and :attr:`bse` (pandas Series by setting name),
    :meth:`conf_int`, :attr:`llf`, :attr:`aic`, :attr:`bic`, :attr:`nobs`, :meth:`summary` (also ``str()``)
    and :meth:`save` (the files of ``kalcal fit --out``).

    Attributes
    ----------
    scenario : str
        ``"accel-gps"``, ``"scale-bias"``, or for a model file its model's name (``[model] name``, as
        fit.json's ``scenario``). imu-3axis and a model written as code have no fit (refused in one line).
    parameters : dict of str to FitParameter
        Keyed by setting name.
    loglik : float
        log L at the estimate, from the prediction-error decomposition of the innovations.
    aic : float
        2 k - 2 log L, k the number of free parameters.
    fixes : int
        The measurements in the likelihood (fixes, or samples for scale-bias).
    converged : bool
        Whether the search converged: the optimizer's verdict, or a Newton step's predicted gain of log L
        over the parameters of the observed information below :data:`~kalcal.fitting.information.GAIN` and the
        projected gradient along the others below :data:`~kalcal.fitting.information.STATIONARY`; and no point
        evaluated for the curves beating the maximum.
    interval_method : {"observed-information", "profile"}
    adequate : bool
        Whether the fitted filter's innovations pass their diagnostics: mean NIS and whiteness, and for
        accel-gps without a gate the NIS tail (:mod:`kalcal.fitting.nis_tail`), at the written point (an
        unresolved latency at its input): an unidentified or unresolved parameter does not by itself make
        it false.
    adequacy : str
        The diagnostics' verdict in words, and when not adequate what the model may lack.
    diagnostics : dict
        The fitted filter's innovation diagnostics.
    curves : dict
        For the figure: per parameter ``{"value": [...], "loglik": [...]}`` around the estimate.
    notes : list of str
        What the user must know about the fit (multipliers used, parameters that cannot be told apart).
    rejected_fixes : list of int or None
        The 1-based GPS rows the innovation gate rejected; None when no gate was used.
    settings : dict
        ``{section: {key: value}}`` for filter.toml; ``comments`` holds a line per key to explain.
    confidence : float
    extra : dict
        More of fit.json (accel-gps: the fitted filter's final ``bias`` and ``bias_std``, m/s^2).
    paths : dict
        The files written, by name, when the fit wrote a folder.
    df_model : int or None
        The parameters the search maximized log L over (k in the AIC; a latency held at its input is not
        one); None for a result not made by a search (then the parameters not held).
    command : str
        The command that made it (``"fit accel-gps"``); "" for a result not made by ``kalcal fit``, which
        has no files to save. With it, fit.json (:meth:`to_dict`) holds ``command``, ``inputs``, ``free``
        and ``settings`` too.
    inputs : dict
        The logs it read, by role (fit.json's ``inputs``).
    free : list of str or None
        The settings fitted (fit.json's ``free``).
    filter_text : str or None
        filter.toml, loadable by ``--config`` of calibrate and verify (a model file's fit: model.toml, the
        file with the fitted values, which they take in place of the original).
    kalibr_text : str or None
        imu.yaml, the fitted noise densities in Kalibr's form, where the scenario's noise has one.
    linear : tuple of str
        The fitted settings drawn on a linear axis in fit.png (the others on a log axis).
    derived : dict of str to FitParameter
        By fitted setting, the same estimate in another form, shown under it (accel-gps: a density's
        per-sample std at the log's rate, its unit saying which rate); its interval maps the setting's
        own. Not in fit.json's parameters (the scenario's part of fit.json holds them).
    bootstrap : BootstrapResult or None
        The parametric bootstrap (``kalcal fit --bootstrap B``, :mod:`kalcal.fitting.bootstrap`): per setting
        the percentile interval, bootstrap standard error and bias, beside the likelihood intervals
        (fit.json's ``bootstrap``); None without one.
    """

    scenario: str
    parameters: dict[str, FitParameter]
    loglik: float
    aic: float
    fixes: int
    converged: bool
    interval_method: str
    adequate: bool
    adequacy: str
    diagnostics: dict[str, Any]
    curves: dict[str, dict[str, list[float]]] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    rejected_fixes: list[int] | None = None
    settings: dict[str, dict[str, Any]] = field(default_factory=dict)
    comments: dict[str, str] = field(default_factory=dict)
    confidence: float = 0.95
    extra: dict[str, Any] = field(default_factory=dict)
    #: the files written, by name, when the fit was given a folder (``kalcal.fit(..., out=...)``)
    paths: dict[str, Any] = field(default_factory=dict)
    df_model: int | None = None
    command: str = ""
    inputs: dict[str, str] = field(default_factory=dict)
    free: list[str] | None = None
    filter_text: str | None = field(default=None, repr=False)
    kalibr_text: str | None = field(default=None, repr=False)
    linear: tuple[str, ...] = ()
    #: what one observation of the likelihood is, for the CLI's title (``fixes``; scale-bias's ``samples``)
    nobs_name: str = "fixes"
    derived: dict[str, FitParameter] = field(default_factory=dict)
    #: the name ``filter_text`` is written under (a model file's fit writes the fitted file, model.toml)
    filter_name: str = "filter.toml"
    bootstrap: Any = None

    def __post_init__(self) -> None:
        if self.interval_method not in INTERVAL_METHODS:
            raise ValueError(f"interval_method: expected one of {INTERVAL_METHODS}, got {self.interval_method!r}")

    @classmethod
    def from_search(cls, scenario: str, fit, **rest: Any) -> FitResult:
        """The result of ``scenario``'s fit from its search (a :class:`kalcal.fitting.mle.MleFit`: the
        parameters, log L, AIC, convergence, interval method, curves and notes, after ``rest``'s) and the
        fields only the scenario knows (``rest``)."""
        notes = [*rest.pop("notes", []), *getattr(fit, "notes", ())]
        return cls(
            scenario=scenario, parameters=fit.parameters, loglik=fit.loglik, aic=fit.aic, converged=fit.converged,
            interval_method=fit.interval_method, curves=fit.curves, notes=notes, df_model=len(fit.values), **rest,
        )

    def value(self, name: str) -> float | None:
        """The estimate of ``name`` (None when unidentified)."""
        return self.parameters[name].value

    # -- the statsmodels shape ------------------------------------------------------------------------

    @property
    def params(self) -> pd.Series:
        """The estimates by setting name, in their units (NaN where unidentified)."""
        import pandas as pd

        return pd.Series({name: _nan(p.value) for name, p in self.parameters.items()}, dtype=float, name="estimate")

    @property
    def bse(self) -> pd.Series:
        """The standard errors of :attr:`params` from the observed information, by setting name: on a log
        scale the delta method's value x se(ln value) (the intervals are asymmetric: :meth:`conf_int`);
        NaN where the interval is not the observed information's Wald one (profile, one-sided, consistent
        with 0, a latency's grid) or the setting is unidentified."""
        import pandas as pd

        return pd.Series({name: _standard_error(p) for name, p in self.parameters.items()}, dtype=float, name="bse")

    def conf_int(self, alpha: float | None = None, level: float | None = None) -> pd.DataFrame:
        """The intervals at ``level`` (or ``1 - alpha``; default the fit's :attr:`confidence`), one row per
        setting, columns ``lower`` and ``upper`` in the setting's unit (NaN: no limit, or unidentified).

        At the fit's own level these are the stored ``ci_low``/``ci_high`` (0 as ``lower`` for an estimate
        consistent with 0). At another level: the Wald interval on the search's scale from the same
        observed information, exp(ln(value) +- z se) for a positive setting (value +- z se on a linear
        scale), z the normal quantile of (1 + level) / 2. A likelihood-ratio interval (profile, one-sided,
        consistent with 0, a latency's grid) holds at the fit's level only: another level raises a
        KalcalError (a ValueError) naming the settings; fit again with ``confidence=level``.
        """
        import pandas as pd

        from kalcal.results._display import level_of, same_level
        from kalcal.errors import KalcalError

        confidence = level_of(alpha, level, self.confidence)
        stored = same_level(confidence, self.confidence)
        rows, refused = {}, []
        for name, p in self.parameters.items():
            if p.value is None:
                rows[name] = (np.nan, np.nan)
            elif stored:
                rows[name] = (_nan(p.ci_low), _nan(p.ci_high))
            elif p.se is not None:
                rows[name] = wald_interval(p, confidence)
            else:
                refused.append(name)
        if refused:
            kind = "profile-likelihood" if self.interval_method == "profile" else "likelihood-ratio"
            raise KalcalError(
                f"conf_int: level {confidence:g}: the {kind} interval of {', '.join(refused)} holds at the fit's "
                f"level {self.confidence:g} only; fit again with confidence={confidence:g}"
            )
        return pd.DataFrame.from_dict(rows, orient="index", columns=["lower", "upper"])

    @property
    def llf(self) -> float:
        """log L at the estimate (:attr:`loglik`)."""
        return self.loglik

    @property
    def nobs(self) -> int:
        """The measurements in the likelihood (:attr:`fixes`: fixes, or samples for scale-bias)."""
        return self.fixes

    @property
    def k(self) -> int:
        """The free parameters counted by :attr:`aic` and :attr:`bic` (:attr:`df_model`)."""
        return self.df_model if self.df_model is not None else sum(not p.held for p in self.parameters.values())

    @property
    def bic(self) -> float:
        """k ln(nobs) - 2 log L (Schwarz), k the free parameters (:attr:`k`)."""
        return self.k * float(np.log(self.nobs)) - 2.0 * self.loglik

    def summary(self) -> str:
        """The fit as a text table, as statsmodels' ``summary()``: log L, AIC, BIC, observations, then per
        setting the estimate, standard error, interval at the fit's level and unit, then the notes."""
        from kalcal.results._display import fmt, text_table

        level = self.confidence
        tail = (1.0 - level) / 2.0
        table = text_table(
            ["setting", "estimate", "std err", f"[{tail:.3g}", f"{1 - tail:.3g}]", "unit"],
            [[name, *row] for name, row in self._rows()],
        )
        width = max(len(line) for line in table)
        facts = [
            ("log-likelihood", fmt(self.llf, 6)), ("AIC", fmt(self.aic, 6)), ("BIC", fmt(self.bic, 6)),
            ("observations", str(self.nobs)), ("free parameters", str(self.k)),
            ("converged", fmt(self.converged)), ("intervals", f"{self.interval_method}, {level:.4g}"),
        ]
        # two facts a line, as statsmodels' header
        left = max(len(f"{name}: {value}") for name, value in facts[0::2]) + 4
        pairs = [
            (f"{facts[i][0]}: {facts[i][1]}".ljust(left) + (f"{facts[i + 1][0]}: {facts[i + 1][1]}" if i + 1 < len(facts) else "")).rstrip()
            for i in range(0, len(facts), 2)
        ]
        width = max(width, *map(len, pairs))
        lines = [f"kalcal fit {self.scenario}".center(width).rstrip(), "=" * width, *pairs, "=" * width, *table, "=" * width]
        lines.append(f"{'adequate' if self.adequate else 'NOT ADEQUATE'}: {self.adequacy}")
        notes = [f"{name}: {p.note}" for name, p in self.parameters.items() if p.note] + list(self.notes)
        lines += [f"[{i}] {note}" for i, note in enumerate(notes, 1)]
        if self.bootstrap is not None:
            lines += ["", *bootstrap_lines(self)]
        return "\n".join(lines)

    def _rows(self) -> list[tuple[str, list[Any]]]:
        """Per setting: estimate, standard error, lower, upper (stored level), unit."""
        ci, se = self.conf_int(), self.bse
        return [(name, [_nan(p.value), se[name], ci.loc[name, "lower"], ci.loc[name, "upper"], p.unit])
                for name, p in self.parameters.items()]

    def __str__(self) -> str:
        return self.summary()

    def __repr__(self) -> str:
        shown = ", ".join(
            f"{name}=" + ("unidentified" if p.value is None else f"{p.value:.4g}") for name, p in self.parameters.items()
        )
        return (f"FitResult({self.scenario}: {shown}; loglik={self.loglik:.6g}, nobs={self.nobs}, "
                f"adequate={self.adequate})")

    def _repr_html_(self) -> str:
        import html

        from kalcal.results._display import html_facts, html_table

        tail = (1.0 - self.confidence) / 2.0
        facts = html_facts(f"kalcal fit {self.scenario}", [
            ("log L", self.llf), ("AIC", self.aic), ("BIC", self.bic), ("observations", self.nobs),
            ("converged", self.converged), ("intervals", f"{self.interval_method} {self.confidence:g}"),
        ])
        table = html_table(["setting", "estimate", "std err", f"[{tail:.3g}", f"{1 - tail:.3g}]", "unit", "note"],
                           [[name, *row, self.parameters[name].note] for name, row in self._rows()])
        verdict = f"<b>{'adequate' if self.adequate else 'NOT ADEQUATE'}</b>: {html.escape(self.adequacy)}"
        boot = ""
        if self.bootstrap is not None:
            boot = (f"<br><b>{html.escape(bootstrap_title(self))}</b>"
                    + html_table(bootstrap_header(self), bootstrap_rows(self)))
        return f"<div>{facts}<br>{verdict}{table}{boot}</div>"

    def save(self, out: str | Path) -> dict[str, Path]:
        """Write ``fit.json``, ``filter.toml`` (a model file's: ``model.toml``), ``fit.png`` and (accel-gps) ``imu.yaml`` into ``out``, as
        ``kalcal fit --out`` does (one set: whole or not at all, docs/outputs.md); returns the files by name."""
        from kalcal.errors import KalcalError

        if not self.command:
            raise KalcalError("save: this FitResult holds no files to write (only kalcal.fit's results do)")
        from kalcal.fitting.run import save_fit

        return save_fit(self, out)

    def to_dict(self) -> dict[str, Any]:
        """fit.json's content (``schema_version`` is added by the writer, :func:`kalcal.io.results.write_json`)."""
        document = {
            "scenario": self.scenario,
            "parameters": {name: parameter.as_dict() for name, parameter in self.parameters.items()},
            "loglik": self.loglik,
            "aic": self.aic,
            "fixes": self.fixes,
            "converged": self.converged,
            "interval_method": self.interval_method,
            "confidence": self.confidence,
            "adequate": self.adequate,
            "adequacy": self.adequacy,
            "diagnostics": self.diagnostics,
            "notes": list(self.notes),
            **self.extra,
            "curves": self.curves,
        }
        if self.bootstrap is not None:
            document["bootstrap"] = self.bootstrap.as_dict()
        if self.rejected_fixes is not None:
            document["rejected_fixes"] = {"count": len(self.rejected_fixes), "rows": list(self.rejected_fixes)}
        if self.command:  # what the command adds: fit.json's provenance and filter.toml's settings
            document.update(command=self.command, inputs=dict(self.inputs), free=list(self.free or []), settings=self.settings)
        return document


def bootstrap_rows(result: FitResult) -> list[list[str]]:
    """Per setting of the bootstrap, beside its likelihood interval (:func:`likelihood_text`): the percentile
    interval, bootstrap standard error and bias (+- its Monte Carlo error) and the note, or "not applicable"
    and why: the rows of :meth:`FitResult.summary`'s and ``_repr_html_``'s bootstrap tables."""
    from kalcal.results._display import fmt

    rows = []
    for name, b in result.bootstrap.parameters.items():
        likelihood = likelihood_text(result.parameters[name])
        if not b.applicable and b.se is None:
            rows.append([name, likelihood, "—", "—", "—", "not applicable: " + b.reason])
            continue
        rows.append([name, likelihood, percentile_text(b), fmt(b.se, 4), f"{b.bias:.3g} +- {b.bias_se:.2g}", bootstrap_note(b)])
    return rows


def bootstrap_header(result: FitResult) -> list[str]:
    """The columns of :func:`bootstrap_rows`: the likelihood interval under the fit's method and level."""
    boot = result.bootstrap
    return ["setting", f"{result.confidence:.0%} {result.interval_method}", f"{boot.confidence:.0%} percentile",
            "boot se", "bias", "note"]


def bootstrap_title(result: FitResult) -> str:
    """The bootstrap table's title: B, the seed and the refits not converged."""
    boot = result.bootstrap
    return (f"parametric bootstrap: {boot.replicates} logs simulated from the fit and refitted, seed {boot.seed}, "
            f"{boot.failed} refit(s) not converged")


def bootstrap_lines(result: FitResult) -> list[str]:
    """The bootstrap's table for :meth:`FitResult.summary` (:func:`bootstrap_rows`), under its title."""
    from kalcal.results._display import text_table

    return [bootstrap_title(result), *text_table(bootstrap_header(result), bootstrap_rows(result))]


def likelihood_text(p: FitParameter) -> str:
    """A setting's likelihood interval as the bootstrap's tables show it beside the percentile one: "[a, b]",
    "[0, b]" for an estimate consistent with 0, "—" for an end the search range does not reach, "—" alone
    for a setting without an estimate."""
    if p.value is None:
        return "—"
    low = "0" if p.at_bound else "—" if p.ci_low is None else f"{p.ci_low:.4g}"
    return f"[{low}, {'—' if p.ci_high is None else f'{p.ci_high:.4g}'}]"


def percentile_text(b) -> str:
    """A bootstrap entry's percentile interval "[low, high]", or "not applicable" (the note says why: an
    applicable entry has both ends, :class:`~kalcal.fitting.bootstrap.BootstrapParameter`)."""
    if not b.applicable:
        return "not applicable"
    return f"[{b.ci_low:.4g}, {b.ci_high:.4g}]"


def bootstrap_note(b) -> str:
    """A bootstrap entry's note: why not applicable, and how many refits ended at an end of the search range."""
    ends = f"{b.at_range_end} refit(s) at an end of the search range" if b.at_range_end else ""
    return "; ".join(text for text in (b.reason, ends) if text)


def _nan(value: float | None) -> float:
    return np.nan if value is None else float(value)


def _standard_error(p: FitParameter) -> float:
    """The standard error of ``p``'s value: se itself on a linear scale, value x se(ln value) on a log one."""
    if p.se is None or p.value is None:
        return np.nan
    return float(p.se) if p.scale == "linear" else float(p.value) * float(p.se)


def wald_interval(p: FitParameter, level: float) -> tuple[float, float]:
    """The Wald interval of ``p`` at ``level`` on its search's scale: u_hat +- z se, z the normal quantile of
    (1 + level) / 2, mapped back (exp on the log scale); ``p.se`` must be set."""
    from kalcal.stats.distributions import normal_isf

    z = float(normal_isf((1.0 - level) / 2.0))
    if p.scale == "linear":
        return float(p.value - z * p.se), float(p.value + z * p.se)
    u = float(np.log(p.value))
    return float(np.exp(u - z * p.se)), float(np.exp(u + z * p.se))


def fitted_point(fit) -> dict[str, float]:
    """The settings the fitted filter runs with: each identified parameter's estimate and, for parameters
    that trade off along a ridge, the point the search reached on it (one point of the ridge: the log
    identifies their combination only); the others keep their input settings (absent)."""
    return {key: value for key, value in fit.values.items()
            if fit.parameters[key].identified or fit.parameters[key].trades_off}


def interval_text(p: FitParameter) -> str:
    """``95% interval [a, b] unit`` or ``consistent with 0, upper limit b unit`` in words."""
    high = "none" if p.ci_high is None else f"{p.ci_high:.4g}"
    if p.at_bound:
        return f"consistent with 0, upper limit {high} {p.unit}"
    return f"interval [{p.ci_low:.4g}, {high}] {p.unit}"
