"""A nonlinear model written as code as a scenario: its settings sections and the Scenario protocol.

Settings (``--set section.key=value``):

- ``model.file``: the Python file (or, for a model given as an object, the name it is registered under);
- ``filter.kind``: ``ekf`` (default), ``iekf`` or ``ukf`` -- a setting, not a model attribute, so that one
  file verifies all three filters; ``filter.alpha``, ``filter.beta``, ``filter.kappa`` (the UKF's sigma
  points), ``filter.max_iterations`` (the IEKF's); ``filter.compiled``: ``auto`` (default), ``yes`` or ``no``,
  whether an EKF runs in the compiled kernel (:attr:`kalcal.scenarios.nonlinear.problem.NonlinearProblem.compiled_path`:
  ``auto`` where it is compiled already or the run repays its compile);
- ``scenario.updates``: K (0: the file's ``N_UPDATES``, else 100);
- ``checks.tolerance``: the tolerance verdicts' band (default 0.1: "P within +-10 % of the mean squared
  error", :mod:`kalcal.stats.effects`);
- ``checks.power_runs``: R, the repeated runs per named alternative of the power by simulation
  (:mod:`kalcal.scenarios.nonlinear.power`; default 0: none, for it costs 4 R runs of N realizations).

The file may define ``DATA``: the data of h, shape (k,) shared by every update or (K, k); and ``INPUTS``,
u, shape (m,) or (K, m).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from kalcal.models.settings import SettingError, show
from kalcal.scenarios.protocol import Capabilities, ScenarioDefaults

FILTER_KINDS = ("ekf", "iekf", "ukf")
#: what each estimator approximates of a nonlinear model: the cause of a failed check where the truth is
#: the filter's own model (:meth:`NonlinearScenario.approximation_cause`)
APPROXIMATIONS = {
    "ekf": ("the EKF's linearization: it propagates the mean and P through the Jacobians at its estimate, so where "
            "the model curves within the prior's spread its mean is biased and its P is first order"),
    "iekf": ("the iterated EKF's linearization: it relinearizes the update at its final iterate, so its P is still "
             "first order (a Gauss-Newton step's) where the model curves within the spread"),
    "ukf": ("the UKF's sigma points: its mean and P are the moments of a few points through the model, exact only "
            "to second order where the model curves within the spread"),
    "batch": ("the batch maximum likelihood's approximation at the final time: its covariance is the inverse "
              "information at the estimate (first order, the Cramér–Rao bound's) and its estimate has a second-order "
              "bias for few measurements"),
}
#: filter.compiled's values (kalcal.scenarios.nonlinear.problem.COMPILED_MODES, which imports numpy's filters)
COMPILED_MODES = ("auto", "yes", "no")
DEFAULT_UPDATES = 100

#: models given as objects (kalcal.verify(NonlinearModel(...))), by the name model.file holds for them:
#: a settings section holds text, and a scenario rebuilt from its settings finds its models here
_OBJECTS: dict[str, Any] = {}


@dataclass(frozen=True)
class NonlinearModelSection:
    """Section ``model``: where the models come from."""

    file: str = ""


@dataclass(frozen=True)
class NonlinearFilterSection:
    """Section ``filter``: which filter runs, and its own settings."""

    kind: str = "ekf"
    alpha: float = 1.0
    beta: float = 2.0
    kappa: float = 0.0
    max_iterations: int = 20
    #: ``auto``, ``yes`` or ``no``: the EKF's compiled kernel (:data:`COMPILED_MODES`)
    compiled: str = "auto"

    def __post_init__(self) -> None:
        if self.kind not in FILTER_KINDS:
            raise SettingError("filter.kind", f"one of {', '.join(FILTER_KINDS)}", show(self.kind))
        if self.compiled not in COMPILED_MODES:
            raise SettingError("filter.compiled", f"one of {', '.join(COMPILED_MODES)}", show(self.compiled))
        if self.max_iterations < 1:
            raise SettingError("filter.max_iterations", "a positive integer", show(self.max_iterations))


@dataclass(frozen=True)
class NonlinearRunSection:
    """Section ``scenario``: the run's length."""

    updates: int = 0  #: K; 0: the file's N_UPDATES, else 100

    def __post_init__(self) -> None:
        if self.updates < 0:
            raise SettingError("scenario.updates", "a positive integer (0: the file's N_UPDATES)", show(self.updates))


@dataclass(frozen=True)
class ChecksSection:
    """Section ``checks``: the tolerance verdicts' band and the power by simulation's repeated runs."""

    tolerance: float = 0.1
    power_runs: int = 0  #: R per alternative; 0: no power by simulation

    def __post_init__(self) -> None:
        if not 0.0 < self.tolerance < 1.0:
            raise SettingError("checks.tolerance", "a number in (0, 1)", show(self.tolerance))
        if isinstance(self.power_runs, bool) or not isinstance(self.power_runs, int) or self.power_runs < 0:
            raise SettingError("checks.power_runs", "a non-negative integer (0: no power by simulation)", show(self.power_runs))


def is_code_model(scenario: Any) -> bool:
    """Whether a SCENARIO argument names a model written as code (a path ending in ``.py``)."""
    return isinstance(scenario, (str, Path)) and str(scenario).lower().endswith(".py")


@dataclass(frozen=True)
class Loaded:
    """The models and the file's extras."""

    truth: Any
    filter: Any
    source: str
    n_updates: int
    data: np.ndarray | None
    inputs: np.ndarray | None


def _load(file: str) -> Loaded:
    if file in _OBJECTS:
        return _OBJECTS[file]
    from kalcal.core.nonlinear import load_nonlinear_model

    models = load_nonlinear_model(file)
    module = models.module
    extra = {}
    for name in ("DATA", "INPUTS"):
        value = getattr(module, name, None)
        extra[name] = None if value is None else np.asarray(value, dtype=float)
    count = int(getattr(module, "N_UPDATES", DEFAULT_UPDATES))
    loaded = Loaded(models.truth, models.filter, file, count, extra["DATA"], extra["INPUTS"])
    _OBJECTS[file] = loaded
    return loaded


def register_models(truth, filter_model, data=None, inputs=None, n_updates: int = DEFAULT_UPDATES) -> str:
    """Register models given as objects; returns the name ``model.file`` holds for them."""
    key = f"<NonlinearModel {id(truth):x}/{id(filter_model):x}>"
    _OBJECTS[key] = Loaded(
        truth, filter_model, key, int(n_updates),
        None if data is None else np.asarray(data, dtype=float), None if inputs is None else np.asarray(inputs, dtype=float),
    )
    return key


@dataclass(frozen=True)
class NonlinearScenario(ScenarioDefaults):
    """A nonlinear model's filter (EKF, IEKF or UKF) against its truth."""

    model: NonlinearModelSection = field(default_factory=NonlinearModelSection)
    filter: NonlinearFilterSection = field(default_factory=NonlinearFilterSection)
    scenario: NonlinearRunSection = field(default_factory=NonlinearRunSection)
    checks: ChecksSection = field(default_factory=ChecksSection)

    NAME: ClassVar[str] = "nonlinear"
    SUMMARY: ClassVar[str] = "a nonlinear model written as code (a .py file), its EKF, IEKF or UKF"

    capabilities: ClassVar[Capabilities] = Capabilities(
        exact_analysis=False,
        fixed_gains=False,
        nonlinear=True,
        engines=("exact",),
        long_run=False,
        commands=frozenset({"verify", "report"}),
        why_not=(
            ("analyze", "no exact analysis: the filter's P is a linearization's, only a Monte Carlo tells its error; use kalcal verify"),
            ("sweep", "no sweep of a model written as code; run kalcal verify with --set"),
            ("simulate", "no log simulation of a model written as code"),
            ("calibrate", "a model written as code has no calibration of logs"),
            ("fit", "a model written as code has no noise fit"),
            ("--engine", "use the exact engine (the truth is simulated at the update times)"),
            ("--long-run", "set scenario.updates instead"),
        ),
    )

    def __post_init__(self) -> None:
        if not self.model.file:
            raise SettingError("model.file", "a Python model file (.py)", show(self.model.file))
        loaded = _load(self.model.file)
        for role, m in (("truth", loaded.truth), ("filter", loaded.filter)):
            if (m.state_dim, m.measurement_dim) != (loaded.filter.state_dim, loaded.filter.measurement_dim):
                raise SettingError(f"{loaded.source}: {role}", "the filter's state and measurement sizes", f"{m.state_dim}, {m.measurement_dim}")

    @property
    def label(self) -> str:
        return f"a model written as code ({self.model.file})"

    @property
    def loaded(self) -> Loaded:
        return _load(self.model.file)

    @property
    def n_updates(self) -> int:
        return self.scenario.updates or self.loaded.n_updates

    def problem(self, form="joseph", residual_pairs: bool = True):
        from kalcal.errors import ConfigError
        from kalcal.scenarios.nonlinear.problem import NonlinearProblem

        if form != "joseph":
            raise ConfigError(f"--form: {form!r} is not available for a model written as code (its EKF updates in Joseph form)")
        return NonlinearProblem(self, residual_pairs=residual_pairs, compiled=self.filter.compiled)

    def model_error_cause(self) -> str:
        l = self.loaded
        return "" if l.truth is l.filter else "the file's truth differing from its filter"

    def approximation_cause(self) -> str:
        """The filter's approximation (:data:`APPROXIMATIONS`) where the file's truth is its filter's model;
        "" where they differ (a failure may then be the model error)."""
        l = self.loaded
        return APPROXIMATIONS[self.filter.kind] if l.truth is l.filter else ""

    def run_length(self) -> tuple[int, float]:
        k = self.n_updates
        return k, k * float(self.loaded.filter.dt)

    def truth_is_filter(self) -> bool:
        """Never claimed: even where the file's truth is its filter, the EKF's P is an approximation, so a
        failure is not a false alarm."""
        return False

    def simulate(self, seed: int, logs=None):
        from kalcal.scenarios.protocol import require

        require(self, "simulate")

    def output_names(self, command: str) -> tuple[str, ...]:
        from kalcal.scenarios.protocol import require

        require(self, command)
        return ()

    def calibrate(self, logs, options):
        from kalcal.scenarios.protocol import require

        require(self, "calibrate")

    def fit(self, logs, options):
        from kalcal.scenarios.protocol import require

        require(self, "fit")
