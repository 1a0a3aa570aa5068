"""What a scenario can do, and the one-line refusal of what it cannot: the capabilities every layer may ask.

:class:`Capabilities` and :func:`require` sit below the scenarios (in the package's root, beside its
errors) so that the exact analysis and the engine can ask a scenario what it has without importing the
scenario packages; :mod:`kalcal.scenarios.protocol` re-exports them with the protocol they belong to.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from kalcal.errors import ConfigError

COMMANDS = frozenset({"verify", "analyze", "sweep", "simulate", "calibrate", "fit", "report"})


@dataclass(frozen=True)
class Capabilities:
    """What a scenario has, asked where kalcal's behaviour depends on it.

    Attributes
    ----------
    exact_analysis : bool
        A linear Gaussian truth filtered with gains fixed before any data: ``kalcal analyze``, the exact
        prediction of the ensemble (self-check) and the checks' power by analysis apply.
    fixed_gains : bool
        P_k and the gains are the same in every realization (one whitening for the whole ensemble).
    rows_from_data : bool
        The measurement rows H_k are taken from data (the regressors), so each realization has its own P_k:
        the report says so where it has no exact analysis (:meth:`no_exact_analysis`).
    nonlinear : bool
        The model is nonlinear and its filter an approximation whose P is a linearization's: a model written
        as code (EKF, IEKF, UKF) and imu-3axis (its EKF, IEKF, UKF or batch ML). It decides why there is
        no exact analysis (:meth:`no_exact_analysis`), and that a verification asks the problem for its
        effect sizes, whose tolerance outcomes stand beside the exact tests (which an approximation fails
        at a large N: :func:`kalcal.api.verification.problem_effects`), and for its power by simulation,
        which it runs where ``checks.power_runs`` asks (else None).
    batch : bool
        One final estimate per realization: only the final-time checks apply.
    engines : tuple of str
        The Monte Carlo engines it has, the default first.
    long_run : bool
        Whether its run's length is a setting (``scenario.duration``), so that a long-run study can extend it.
    commands : frozenset of str
        The commands it supports, of :data:`COMMANDS`.
    why_not : tuple of (str, str)
        For a command it lacks, why (the refusal's reason); a command absent here is refused as unsupported.
        ``"--engine"`` and ``"--long-run"`` give the reason for an engine it lacks and for a long run
        where ``long_run`` is False.
    """

    exact_analysis: bool
    fixed_gains: bool
    rows_from_data: bool = False
    nonlinear: bool = False
    batch: bool = False
    engines: tuple[str, ...] = ("exact",)
    long_run: bool = True
    commands: frozenset[str] = COMMANDS
    why_not: tuple[tuple[str, str], ...] = ()

    def __post_init__(self) -> None:
        unknown = set(self.commands) - COMMANDS
        unknown |= {key for key, _ in self.why_not} - COMMANDS - {"--engine", "--long-run"}
        if unknown:
            raise ValueError(f"unknown commands {sorted(unknown)}; expected some of {sorted(COMMANDS)}")
        if self.exact_analysis and not self.fixed_gains:
            raise ValueError("an exact analysis needs fixed gains")

    def no_exact_analysis(self) -> str:
        """Why there is no exact analysis, in words that fit in parentheses ("" where there is one): a
        nonlinear model's P is a linearization's; rows from data make each realization's gains its own."""
        if self.exact_analysis:
            return ""
        if self.nonlinear:
            return "its filter's P is a linearization's: the gains depend on the state"
        if self.rows_from_data:
            return "its filter's gains depend on the noisy readings: the measurement rows are data, so each realization has its own P"
        return "its filter's gains depend on the data"


def require(scenario: Any, command: str, *, engine: str | None = None, long_run: bool = False) -> None:
    """Refuse ``command`` (and ``engine``, and a long run where ``long_run``) where ``scenario`` lacks it:
    one line naming the scenario and why (a :class:`~kalcal.errors.ConfigError`, exit status 2)."""
    caps = scenario.capabilities
    name = getattr(scenario, "label", None) or scenario.NAME
    why = dict(caps.why_not)
    if command not in caps.commands:
        raise ConfigError(f"{name}: {why.get(command, f'{name} has no {command}')}")
    if engine is not None and engine not in caps.engines:
        raise ConfigError(f"--engine: {engine!r} is not available for {name}; {why.get('--engine', 'use ' + ' or '.join(caps.engines))}")
    if long_run and not caps.long_run:
        raise ConfigError(f"--long-run: not available for {name}; {why.get('--long-run', 'its run has no duration setting')}")
