"""The Scenario protocol: what the engine, the checks, the analysis, the report, the API and the CLI ask of a scenario.

Whatever differs between scenarios is a method here or a capability, never a test of a scenario's name or
class outside its package (tests/scenarios/test_scenario_boundary.py holds that). The capabilities are
the questions the rest of kalcal used to answer by asking which scenario it had: whether an exact
analysis exists, whether P is the same in every realization, whether the measurement rows come from
data, whether the model is nonlinear, whether the estimator is a batch one; and which engines and
commands the scenario has. A command a scenario lacks is refused in one line that names the scenario
and why (:func:`require`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar, Protocol, runtime_checkable

from kalcal.capabilities import COMMANDS, Capabilities, require
from kalcal.errors import ConfigError

__all__ = ["COMMANDS", "Capabilities", "Scenario", "ScenarioDefaults", "refuse_logs", "require"]


@runtime_checkable
class Scenario(Protocol):
    """A scenario: settings, a model, a simulation, and the answers the rest of kalcal asks of it."""

    NAME: ClassVar[str]  #: what the registry and summary.json call it
    SUMMARY: ClassVar[str]  #: one line for --help and the docs

    def given_section(self, name: str) -> Any:
        """The settings section ``name`` as given, for the settings layer to change and replace
        (:func:`kalcal.models.config.apply_settings`): the field itself where the scenario keeps no other
        (``getattr(self, name)``); accel-gps's ``truth`` as given (a density, an unset value), beside the
        field that holds it resolved per sample at the run's rate, so that a changed rate converts it anew."""
        ...

    @property
    def state_labels(self) -> tuple[str, ...] | None:
        """What each of the filter's states is, for the realization figures' titles (accel-gps: its error
        states ``δp = p − p_c``, ...), length d; None where the problem's state names say it."""
        ...

    def source_report(self) -> bool:
        """Whether these settings are the source report's setup: the page quotes its figure numbers and
        summary.json gives E[r_k r_j^T] at its pair of times only then (elsewhere they would name another
        study's numbers). A question of the settings, not of the scenario's class: a run of the report's
        scenario with another scheme or other fixes is not the report's study."""
        ...

    def residual_pair_times(self) -> tuple[float, float] | None:
        """(t_k, t_j), s: the pair of update times at which summary.json gives E[r_k r_j^T] (the source
        report's pair, for its setup alone: :meth:`source_report`); None where the scenario quotes none."""
        ...

    @property
    def capabilities(self) -> Capabilities:
        """What it has: a class's own constant for a built-in, a property of the instance for a model file
        (its commands and engines, and the reasons it names, depend on its content and its file)."""
        ...

    def problem(self, form: str = "joseph", residual_pairs: bool = True) -> Any:
        """The verification problem (:class:`~kalcal.montecarlo.problem.Problem`): its filter against its truth.

        ``residual_pairs=False`` skips E[r_k r_j^T] over all pairs (and so the whiteness check)."""
        ...

    def model_error_cause(self) -> str:
        """A sentence naming what makes the truth depart from the filter's model ("" for none), for check details."""
        ...

    def check_settings(self, command: str) -> None:
        """Refuse (a one-line SettingError) a setting that ``command`` cannot honour."""
        ...

    def approximation_cause(self) -> str:
        """Where the truth is the filter's own model and the filter approximates it (a nonlinear model's
        EKF, IEKF, UKF or batch estimator), a phrase naming the approximation, the cause of any failed check
        ("" otherwise: a failure's cause is the checks' own)."""
        ...

    def error_sources(self) -> list[Any]:
        """The error budget's independent sources (:class:`~kalcal.core.sources.Source`) of the exact analysis."""
        ...

    def noise_settings(self) -> dict[str, Callable[[float], Any]]:
        """The truth's noise settings, each as factor -> the scenario with that setting's std times ``factor``
        (the filter's settings held): what the sensitivity scales."""
        ...

    def default_long_run(self, max_updates: int) -> float:
        """The long-run study's horizon (s) when none is given (0: none), within ``max_updates`` updates."""
        ...

    def run_length(self) -> tuple[int, float]:
        """(K, t_K): the filter updates of one realization and the last update's time (s), from the settings
        alone (no arrays are built): what a verification sizes its arrays and its long run by."""
        ...

    def truth_is_filter(self) -> bool:
        """Whether its settings make the truth the filter's own model, where no exact analysis says so."""
        ...

    def simulate(self, seed: int, logs: dict[str, Any] | None = None) -> Any:
        """One realization drawn with ``seed``, as logs (:class:`kalcal.results.simulation.SimulationResult`).

        ``logs`` (``{"data": path or DataFrame}``, as :meth:`calibrate` takes them) is for a scenario whose
        simulation keeps a given log's rows (a model file: its times, inputs and data columns); a scenario
        that draws its own logs refuses a given one in one line (:func:`refuse_logs`)."""
        ...

    def over_log(self, data: Any, command: str, topic: str | None = None) -> Any:
        """The scenario verified over the log ``data`` (``--data LOG``: a model file's rows from a log;
        ``topic``: a bag's or ULog's topic), or a one-line refusal for one that simulates its own data."""
        ...

    #: the settings a command on logged data (calibrate, fit) starts from, before the user's
    LOG_DEFAULTS: ClassVar[dict[str, Any]]
    #: the options of :class:`~kalcal.results.calibration.CalibrateOptions` its ``calibrate`` takes (a
    #: refusal of another names the scenarios that take it, from the registry)
    CALIBRATE_OPTIONS: ClassVar[tuple[str, ...]]

    def output_names(self, command: str) -> tuple[str, ...]:
        """The files ``command`` (``"simulate"``, ``"calibrate"``, ``"fit"``) writes, for its staged set."""
        ...

    def calibrate(self, logs: dict[str, Any], options: Any) -> Any:
        """The calibration of ``logs`` (the scenario's own: ``imu`` and ``gps``, or ``data``; paths or
        DataFrames; a log it does not read, or one missing, refused in one line) with ``options``
        (:class:`~kalcal.results.calibration.CalibrateOptions`): a
        :class:`~kalcal.results.calibration.CalibrationResult` (or the scenario's subclass of it)."""
        ...

    def fit(self, logs: dict[str, Any], options: Any) -> Any:
        """The noise settings fitted to ``logs`` by maximum likelihood with ``options``
        (:class:`~kalcal.fitting.run.FitOptions`): the :class:`~kalcal.fitting.result.FitResult` it made,
        with what its files need (:func:`~kalcal.fitting.run.for_command`): ``to_dict()`` is fit.json and
        ``save(out)`` writes the set.

        With ``options.bootstrap`` = B > 0 the scenario's own part of the parametric bootstrap is its hook
        ``draw(rng)``: one log simulated from its fitted model with the given log's length, sampling, missing
        measurements and inputs, returned as that log's log-likelihood of the settings; it hands the hook,
        its search's parameters and its search to :func:`kalcal.fitting.bootstrap.bootstrap_fit`, which
        seeds, refits and summarizes, and puts the result in the FitResult's ``bootstrap``. A scenario that
        cannot simulate its log refuses ``--bootstrap`` in one line."""
        ...


class ScenarioDefaults:
    """The protocol's answers for a scenario with nothing of its own to say: every section kept as given,
    its state names as labels, not the source report's setup (nor its residual pair), no log defaults, no
    verification over a log, and, for a scenario without an exact analysis, nothing to refuse, no error
    sources, no noise settings to scale and no long-run study. A scenario inherits this and overrides what
    differs (accel-gps its settings' checks and long run; accel-gps and the model file, whose exact analyses
    they are, their error sources and noise settings)."""

    LOG_DEFAULTS: ClassVar[dict[str, Any]] = {}
    #: the options of :class:`~kalcal.results.calibration.CalibrateOptions` its calibrate takes: none
    CALIBRATE_OPTIONS: ClassVar[tuple[str, ...]] = ()

    def given_section(self, name: str) -> Any:
        """The section ``name`` itself: every section is kept as given."""
        return getattr(self, name)

    @property
    def state_labels(self) -> None:
        """None: its state names say what each state is."""
        return None

    def source_report(self) -> bool:
        """False: the source report studied the accelerometer/GPS setup alone."""
        return False

    def residual_pair_times(self) -> None:
        """None: no pair of times is quoted from another study."""
        return None

    def check_settings(self, command: str) -> None:
        """Nothing to refuse beyond the sections' own checks."""

    def approximation_cause(self) -> str:
        """"": the checks' own causes stand (a linear filter, or a truth that is not the filter's model)."""
        return ""

    def error_sources(self) -> list:
        """None: the error budget's sources belong to an exact analysis."""
        return []

    def noise_settings(self) -> dict:
        """None to scale: the sensitivity needs an exact analysis."""
        return {}

    def default_long_run(self, max_updates: int) -> float:
        """0: no long-run study."""
        return 0.0

    def over_log(self, data: Any, command: str, topic: str | None = None) -> Any:
        """Refused: only a model file's [data] table binds a verification to a log (``--data LOG``); the
        built-in scenarios and models written as code simulate their own data."""
        raise ConfigError(
            f"--data: {command} runs a log through a model file's [data] table; the built-in scenarios simulate their own data"
        )


def refuse_logs(scenario: Any, logs: dict[str, Any] | None, command: str = "simulate") -> None:
    """Refuse, in one line, a log given to ``command`` of a scenario that draws its own (a built-in's
    simulate): the first log given, by its option (a :class:`~kalcal.errors.ConfigError`, exit status 2)."""
    given = [name for name, value in (logs or {}).items() if value is not None]
    if given:
        name = getattr(scenario, "label", None) or scenario.NAME
        raise ConfigError(f"--{given[0]}: not used by {command} {name} (it draws its own logs)")
