"""What a maximum-likelihood fit of noise settings found: each parameter, the fit's quality, fit.json's layout."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

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
        sample scale for an interval (:mod:`kalcal.fitting.latency_scan`).
    at_bound : bool
        True when the log-likelihood at the search range's lower end is within the drop of the maximum:
        the estimate is consistent with 0 and ``ci_high`` is an upper limit.
    note : str
        A plain sentence for the user when one is due ("" otherwise).
    trades_off : tuple of str
        The parameters this one trades off with along a ridge of log L (unidentified: only their
        combination is); () otherwise. Not in fit.json's entry (the ``note`` names them).
    held : bool
        True for a latency the fit could not resolve (:mod:`kalcal.fitting.latency_scan`): unidentified,
        held at its input while the other settings were refitted. Not in fit.json's entry (the ``note``
        says it).
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


@dataclass(frozen=True)
class FitResult:
    """A fit of one log's noise settings by maximum likelihood.

    Attributes
    ----------
    scenario : str
        ``"accel-gps"`` or ``"scale-bias"``.
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
            interval_method=fit.interval_method, curves=fit.curves, notes=notes, **rest,
        )

    def value(self, name: str) -> float | None:
        """The estimate of ``name`` (None when unidentified)."""
        return self.parameters[name].value

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
        if self.rejected_fixes is not None:
            document["rejected_fixes"] = {"count": len(self.rejected_fixes), "rows": list(self.rejected_fixes)}
        return document


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
