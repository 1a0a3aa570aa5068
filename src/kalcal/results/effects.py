"""A verification's run-level effect sizes, Cramér–Rao rows and power by simulation as typed dataclasses.

Frozen dataclasses built from ``summary.json``'s ``effect_sizes``, ``cramer_rao`` and ``power_by_simulation``
(:attr:`kalcal.results.verification.VerificationResult.effect_sizes`, ...).

Each is built from the summary's dict key for key (a key the dataclass does not name is an error, so a
summary and its types cannot drift apart unseen); arrays come back as numpy arrays.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np


def _array(value) -> np.ndarray | None:
    return None if value is None else np.asarray(value, dtype=float)


@dataclass(frozen=True)
class RunEffectSizes:
    """The run's effect sizes over every update (``summary.json``'s ``effect_sizes``).

    Attributes
    ----------
    tolerance : float
        The tolerance band's half-width (``checks.tolerance``: 0.1 is "P within +-10 %").
    verdict : {"pass", "fail", "undecided"}
        The tolerance verdict of the effects together.
    overall : tuple of EffectSize
        Each effect size with its confidence interval and tolerance outcome
        (:class:`kalcal.stats.effects.EffectSize`).
    per_update : dict of str to ndarray
        Per-update estimates with their confidence interval by effect name, the last axis (value, lower,
        upper): ``nees_per_dim`` (K, 3), ``variance_ratio`` (K, d, 3), ``bias_sigma`` (K, d, 3); dimensionless.
    """

    tolerance: float
    verdict: str
    overall: tuple
    per_update: dict[str, np.ndarray]

    @classmethod
    def from_summary(cls, d: dict[str, Any]) -> RunEffectSizes:
        from kalcal.stats.effects import EffectSize

        return cls(
            tolerance=float(d["tolerance"]), verdict=str(d["verdict"]),
            overall=tuple(EffectSize(**row) for row in d["overall"]),
            per_update={name: np.asarray(value, dtype=float) for name, value in d["per_update"].items()},
        )


@dataclass(frozen=True)
class CramerRaoState:
    """One state's row of the bound at the final update.

    Attributes
    ----------
    state, unit : str
        The state's name and the unit of its squared error, e.g. ``(m)^2``.
    lower_bound : float or None
        (J_K^-1)_ii, in ``unit``; None where no bound is given.
    lower_bound_se : float or None
        The bound's own Monte Carlo standard error (delete-one-group jackknife over the run's independent
        blocks), in ``unit``; None where no bound is given or the run kept fewer than two groups.
    mse, mse_se : float
        The ensemble's mean squared error and its Monte Carlo standard error, in ``unit``.
    difference_se : float or None
        The jackknife's standard error of mse - lower_bound, in ``unit`` (None likewise).
    efficiency : float or None
        lower_bound / mse (at most about 1).
    below_bound : bool or None
        The MSE below the bound beyond the Monte Carlo error of their difference at the run's confidence
        (``difference_se``; the MSE's error alone where that is None).
    below_bound_error : str
        What of the Monte Carlo error ``below_bound`` counts.
    """

    state: str
    unit: str
    lower_bound: float | None
    mse: float
    mse_se: float
    efficiency: float | None
    below_bound: bool | None
    below_bound_error: str
    lower_bound_se: float | None = None
    difference_se: float | None = None


@dataclass(frozen=True)
class CramerRaoSummary:
    """The posterior Cramér–Rao bound against the ensemble's MSE (``summary.json``'s ``cramer_rao``).

    Attributes
    ----------
    note : str
        What the bound bounds.
    available : bool
        Whether a bound is given (``method`` says which recursion, or why none).
    method : str
    final : tuple of CramerRaoState
        Per state at the final update.
    bound_diagonal : ndarray, shape (K, d), or None
        diag J_k^-1 at every update, states' units squared.
    mse, mse_se : ndarray, shape (K, d)
        The ensemble's MSE and its Monte Carlo standard error at every update.
    bound_diagonal_se : ndarray, shape (K, d), or None
        The jackknife's standard error of ``bound_diagonal`` (None where the run kept fewer than two groups).
    jackknife_groups : int or None
        The number of independent groups of blocks the jackknife used.
    """

    note: str
    available: bool
    method: str
    final: tuple[CramerRaoState, ...]
    bound_diagonal: np.ndarray | None
    mse: np.ndarray
    mse_se: np.ndarray
    bound_diagonal_se: np.ndarray | None = None
    jackknife_groups: int | None = None

    @classmethod
    def from_summary(cls, d: dict[str, Any]) -> CramerRaoSummary:
        return cls(
            note=str(d["note"]), available=bool(d["available"]), method=str(d["method"]),
            final=tuple(CramerRaoState(**row) for row in d["final"]), bound_diagonal=_array(d["bound_diagonal"]),
            mse=_array(d["mse"]), mse_se=_array(d["mse_se"]), bound_diagonal_se=_array(d.get("bound_diagonal_se")),
            jackknife_groups=d.get("jackknife_groups"),
        )

    def state(self, name: str) -> CramerRaoState:
        """The row of the state ``name`` (KeyError naming the states where there is none)."""
        for row in self.final:
            if row.state == name:
                return row
        raise KeyError(f"no state {name!r} in the Cramér-Rao rows: {[r.state for r in self.final]}")


@dataclass(frozen=True)
class PowerRow:
    """One check's rejection rate under one alternative, by simulation.

    Attributes
    ----------
    alternative : str
    check : str
    runs : int
        R, the repeated runs.
    exact_rejections : int
        Runs whose exact verdict failed.
    exact_rate, exact_lower, exact_upper : float
        The rate and its Clopper–Pearson interval at ``confidence``.
    tolerance_rejections : int or None
        Runs whose tolerance verdict failed (an effect wholly outside its band); None for a check with no
        effect size.
    tolerance_rate, tolerance_lower, tolerance_upper : float or None
    tolerance_undecided : int or None
        Runs whose tolerance verdict was undecided.
    """

    alternative: str
    check: str
    runs: int
    exact_rejections: int
    exact_rate: float
    exact_lower: float
    exact_upper: float
    tolerance_rejections: int | None
    tolerance_rate: float | None
    tolerance_lower: float | None
    tolerance_upper: float | None
    tolerance_undecided: int | None

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class PowerBySimulation:
    """Each check's rejection rate under named alternatives by repeated runs (``summary.json``'s
    ``power_by_simulation``): an estimate by simulation with Clopper–Pearson intervals, not an exact power.

    Attributes
    ----------
    method, note : str
    runs : int
        R, the repeated runs per alternative.
    realizations : int
        N of each run.
    confidence : float
        The intervals' confidence.
    alternatives : dict of str to str
        Each alternative's name and what it changes.
    rows : tuple of PowerRow
        Per alternative and check (:class:`PowerRow`).
    """

    method: str
    note: str
    runs: int
    realizations: int
    confidence: float
    alternatives: dict[str, str]
    rows: tuple

    @classmethod
    def from_summary(cls, d: dict[str, Any]) -> PowerBySimulation:
        return cls(
            method=str(d["method"]), note=str(d["note"]), runs=int(d["runs"]), realizations=int(d["realizations"]),
            confidence=float(d["confidence"]), alternatives=dict(d["alternatives"]),
            rows=tuple(PowerRow(**row) for row in d["rows"]),
        )

    def rate(self, alternative: str, check: str):
        """The row of one alternative and check (KeyError where there is none)."""
        for row in self.rows:
            if row.alternative == alternative and row.check == check:
                return row
        raise KeyError(f"no power row for alternative {alternative!r} and check {check!r}")
