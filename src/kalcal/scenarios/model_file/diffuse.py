"""A model file whose filter starts diffuse, verified and analyzed: exact diffuse gains, computed once.

The filter's prior is P = P_* + kappa P_inf, kappa -> infinity, in the states the file names ``diffuse``
(:mod:`kalcal.core.timevarying_filter`: Koopman's exact initial recursion, each measured component
decorrelated by the Cholesky factor of V_k and updated in turn). Where every realization has the same rows
(a time-invariant file, or the rows of a log: ``verify --data LOG``), that recursion does not involve the
data: its gains are the same in every realization and are computed once, like the fixed-gain engine's.
Per update k (0-based) with the interval's Phi_k, Q_k and the rows H_k, V_k::

    predict:  P_* = Phi_k P_* Phi_k^T + Q_k,   P_inf = Phi_k P_inf Phi_k^T
    update:   per decorrelated component (h, 1): F_inf = h P_inf h^T;  F_inf > 0: K0 = P_inf h^T / F_inf,
              x += K0 e, P_* = (I - K0 h) P_* (I - K0 h)^T + K0 K0^T, P_inf -= K0 F_inf K0^T;
              F_inf = 0: the ordinary (Joseph) update of P_*

and the row's gain G_k is the composition of its components' (x^+ = xbar + G_k (z_k - H_k xbar)). Once
the prior of an update is proper (P_inf = 0, the rule of :data:`~kalcal.core.timevarying_filter.DIFFUSE_TOL`)
the ordinary covariance pass goes on from the last posterior P_*, in the run's form.

**What is checked.** The *diffuse period* is updates 1..k (1-based), k the update whose measurement
determines the last diffuse direction: from update k + 1 on the filter's prior, its innovation
covariance S and its posterior P are finite. The estimate from then on is a linear function of the
measurements alone in the diffuse directions (its weight on the diffuse states' prior is zero), and P_*
is the covariance of its error whatever the world's prior of those states, as long as the world has one
(a proper [truth] m0: a diffuse truth is not a model of a world). So from update k + 1 on every check means
what it means for a proper filter: the mean error is zero, the error covariance is P, the NEES and NIS
have their chi-square means, the innovations are white (among the checked updates). During the diffuse
period P and S are infinite in the diffuse directions: no check is made there. The estimate at update k
itself is proper, but its innovation is not; it is left out with the rest of the period, so that every
check covers the same updates. The Monte Carlo runs every update (the checked ones depend on the
measurements of the diffuse period) and the statistics, the exact analysis and the report hold the checked
updates alone (:class:`CheckedWindowProblem`); ``summary.json`` and ``analysis.json`` say
``not_checked: "the diffuse period, updates 1..k"``.

Refused in one line: a diffuse period that does not end within the run (the measurements never determine
the diffuse states: nothing could be checked), and a file whose [truth] gives no m0 of its own (the world
would take the filter's, with no variance in the diffuse states: :func:`truth_prior_refusal`; simulate
refuses it alike). A diffuse truth cannot be written: ``[truth]`` has no ``diffuse`` key.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from kalcal.core.steps import GainSchedule, UpdateForm, gain_and_covariance, interval_transition, predict_covariance
from kalcal.core.timevarying_filter import diffuse_step, predict_diffuse
from kalcal.errors import ConfigError
from kalcal.montecarlo.accumulators import BlockResult, MomentSums
from kalcal.montecarlo.problem import FixedGainProblem, ProblemDefaults, ProblemInfo
from kalcal.scenarios.model_file.logged import LoggedGainProblem, covariance_pass_over

__all__ = ["CheckedWindowProblem", "DiffuseFixedGainProblem", "diffuse_schedule", "not_checked", "never_ends"]

_ONE = np.ones((1, 1))

#: why the orthogonality check is left out of a diffuse filter's checks
NO_ORTHOGONALITY = (
    "E[e xhat^T] = 0 holds for a posterior mean, and a diffuse filter's estimate ignores the world's prior of "
    "the diffuse states: its error correlates with its estimate (as a batch estimator's does), by an amount "
    "that does not depend on that prior (the exact analysis gives it)"
)


def not_checked(first: int) -> str:
    """The words ``summary.json`` gives the updates left out of the checks: the diffuse period, 1..first."""
    return f"the diffuse period, updates 1..{first}" if first > 1 else "the diffuse period, update 1"


def never_ends(states, updates: int) -> str:
    """Why a diffuse filter whose diffuse period does not end within the run is refused (after ``FILE:``)."""
    return (
        f"its filter starts diffuse in {', '.join(states)} and its diffuse period takes all {updates} updates of the "
        "run (the prior stays infinite in a diffuse direction up to the last update), so no update is left to check: "
        "measure those states, run more updates, or give them a proper m0"
    )


def truth_prior_refusal(scenario) -> str:
    """Why a diffuse filter is not verified or analyzed ("" where it is), in words that follow ``FILE:``: its
    [truth] gives no m0 of its own, so the world would take the filter's, which has no variance in the
    diffuse states (a world that starts exactly at x0 there: not what a diffuse start says of it). A truth
    with its own states (a map) has its own m0."""
    if not scenario.filter.diffuse or scenario.truth_map is not None or "m0" in scenario.differing():
        return ""
    return (
        f"its filter starts diffuse in {', '.join(scenario.filter.diffuse)} and it has no [truth] m0: give [truth] m0 "
        "(the world's proper prior) to verify or analyze it"
    )


def _placeholder(n: int, size: int) -> np.ndarray:
    """Identity matrices for the diffuse period's P and S, which are infinite: the compiled kernels whiten
    every update, and what they sum there is never read (the checks start after the period)."""
    return np.broadcast_to(np.eye(size), (n, size, size)).copy()


def diffuse_schedule(
    transitions: np.ndarray,
    process_cov: np.ndarray,
    h: np.ndarray,
    v: np.ndarray,
    m0: np.ndarray,
    diffuse: np.ndarray,
) -> tuple[GainSchedule, int, np.ndarray]:
    """The exact diffuse recursion's gains over the diffuse period (module docstring).

    Parameters
    ----------
    transitions, process_cov : ndarray, shape (K, d, d)
        Phi_k and Q_k of each update's interval (states' units).
    h : ndarray, shape (K, p, d)
        H_k, the measured components' rows.
    v : ndarray, shape (K, p, p)
        V_k, positive definite (the measurements' units squared).
    m0 : ndarray, shape (d, d)
        P_* at the start: the file's m0 (zero rows and columns in the diffuse states).
    diffuse : ndarray of bool, shape (d,)
        The states started with P_inf = 1.

    Returns
    -------
    schedule : GainSchedule
        Gains K_k (K, d, p) of the diffuse period's updates 0..first-1 (the rest zero, for the caller to
        fill); identity placeholders for their P, M and S (infinite in the diffuse directions).
    first : int
        The first update (0-based) whose prior is proper; K when the period does not end within the run.
    cov : ndarray, shape (d, d)
        P_* after update first - 1 (m0 for first = 0): the proper posterior the ordinary pass predicts from.
    """
    n_updates, p, d = h.shape
    gains = np.zeros((n_updates, d, p))
    cov = np.array(m0, dtype=float)
    inf: np.ndarray | None = np.diag(np.asarray(diffuse, dtype=float))
    first = n_updates
    for k in range(n_updates):
        inf = predict_diffuse(inf, transitions[k])
        if inf is None:  # Phi_k maps every diffuse direction to zero: update k's prior is proper
            first = k
            break
        cov = predict_covariance(cov, transitions[k], process_cov[k])
        # decorrelate the row (z* = L^{-1} z, h* = L^{-1} H) and carry d xhat / d z (d, p) through its
        # scalar updates: the composition of affine updates is xbar + G (z - H xbar), G its value at xbar = 0
        lower = np.linalg.cholesky(v[k])
        hs = np.linalg.solve(lower, h[k])
        zs = np.linalg.solve(lower, np.eye(p))
        slope = np.zeros((d, p))
        for i in range(p):
            row = hs[i]
            e = zs[i] - row @ slope  # d e / d z of this component's innovation
            step = None if inf is None else diffuse_step(cov, inf, row)  # the log filter's own step
            if step is not None:
                slope = slope + np.outer(step.gain, e)
                cov, inf = step.cov, step.inf
                continue
            gain, cov, _ = gain_and_covariance(cov, row[None, :], _ONE, "joseph")
            slope = slope + np.outer(gain[:, 0], e)
        gains[k] = slope
        if inf is None:  # the posterior is proper: the next prior is, and the ordinary pass takes over
            first = k + 1
            break
    prior, posterior, innovation = _placeholder(n_updates, d), _placeholder(n_updates, d), _placeholder(n_updates, p)
    schedule = GainSchedule(prior, posterior, gains, innovation, np.eye(d), np.zeros((d, d)), np.ascontiguousarray(transitions))
    return schedule, first, cov


def complete_schedule(
    schedule: GainSchedule, first: int, tail: GainSchedule, phi_interval: np.ndarray, q_interval: np.ndarray
) -> GainSchedule:
    """The diffuse period's gains (updates < first) followed by the ordinary pass's ``tail`` (updates first..)."""
    out = {}
    for name in ("prior_cov", "posterior_cov", "gain", "innovation_cov"):
        full = np.array(getattr(schedule, name))
        full[first:] = getattr(tail, name)
        out[name] = full
    return GainSchedule(**out, phi_interval=phi_interval, q_interval=q_interval, transitions=schedule.transitions)


def diffuse_flags(scenario) -> np.ndarray:
    """The filter's diffuse states as (d,) bool, in the order of the file's state names."""
    return np.array([name in scenario.filter.diffuse for name in scenario.model.state_names], dtype=bool)


def refuse_never_ending(scenario, first: int, updates: int) -> None:
    """One line, naming the file, where the diffuse period takes every update of the run."""
    if first >= updates:
        raise ConfigError(f"{scenario.model.file}: {never_ends(scenario.filter.diffuse, updates)}")


@dataclass(frozen=True)
class DiffuseFixedGainProblem(FixedGainProblem):
    """:class:`~kalcal.montecarlo.problem.FixedGainProblem` of a time-invariant file whose filter starts
    diffuse: the exact diffuse gains over the diffuse period, then the ordinary pass (module docstring).
    ``filter_model.x0`` is zero in the diffuse states (the exact filter's start; the estimate after the
    period does not depend on it). ``first`` is set from the schedule: the first update whose prior is
    proper (``truth.n_updates`` when there is none)."""

    diffuse: np.ndarray | None = None  #: (d,) bool, the filter's diffuse states
    first: int = field(init=False, default=0)

    def __post_init__(self) -> None:
        from kalcal.core.steps import covariance_pass

        model, n_updates = self.filter_model, self.truth.n_updates
        d, p = model.state_dim, model.measurement_dim
        if (self.truth.error_dim, self.truth.h.shape[0]) != (d, p):
            raise ValueError(f"truth: expected {d} filter states and {p} measurements")
        phi_m, q_m = interval_transition(model.phi, model.gamma, model.w, model.steps_per_update)
        many = (n_updates, d, d)
        schedule, first, cov = diffuse_schedule(
            np.broadcast_to(phi_m, many), np.broadcast_to(q_m, many), np.broadcast_to(model.h, (n_updates, p, d)),
            np.broadcast_to(model.v, (n_updates, p, p)), model.m0, self.diffuse,
        )  # fmt: skip
        object.__setattr__(self, "first", first)
        if first < n_updates:
            tail = covariance_pass(dataclasses.replace(model, m0=cov), n_updates - first, self.form)
            schedule = complete_schedule(schedule, first, tail, phi_m, q_m)
        self._adopt(schedule)


def _window(value: Any, first: int, n_updates: int) -> Any:
    """An array's updates from ``first`` on, where its leading axis is the updates."""
    if isinstance(value, np.ndarray) and value.ndim >= 1 and value.shape[0] == n_updates:
        return value[first:]
    return value


def window_sums(sums: MomentSums, first: int, n_updates: int, p: int) -> MomentSums:
    """The sums of the updates from ``first`` on (the pairs' upper triangle likewise: rows and columns from
    update ``first``'s first component)."""
    values = {f.name: _window(getattr(sums, f.name), first, n_updates) for f in dataclasses.fields(sums)}
    if sums.residual_outer is not None:
        values["residual_outer"] = np.ascontiguousarray(sums.residual_outer[first * p :, first * p :])
    return MomentSums(**values)


@dataclass(frozen=True)
class CheckedWindowProblem(ProblemDefaults):
    """A fixed-gain problem run over every update and reported over its updates from ``first`` on.

    Every realization runs the ``full`` problem (the updates before ``first`` move the estimates after it);
    the engine, the checks, the statistics files, the exact analysis and the report see the updates from
    ``first`` on alone, as if the run had only those: its ``info`` (times from ``first``), its sums, its
    realizations shown, its expected mean error, its schedule. What ``not_checked`` says stands in the
    run's summary.

    Parameters
    ----------
    full : FixedGainProblem
        The problem over every update (a :class:`DiffuseFixedGainProblem` or a diffuse one over a log).
    first : int
        The first reported update (0-based), 0 < first < K.
    filter_model : object
        What the steady-state view takes for the filter's model (the file's, time-invariant) where
        ``steady_reason`` is ""; else not used.
    steady_reason : str
        Why the filter has no steady state ("" where the DARE applies).
    """

    full: Any
    first: int
    filter_model: Any
    steady_reason: str = ""
    info: ProblemInfo = field(init=False)
    schedule: GainSchedule = field(init=False)

    def __post_init__(self) -> None:
        full, first = self.full, self.first
        n_updates = full.truth.n_updates
        if not 0 < first < n_updates:
            raise ValueError(f"first: expected an update in (0, {n_updates}), got {first}")
        info = dataclasses.replace(
            full.info, update_times=np.asarray(full.info.update_times)[first:], not_checked=not_checked(first),
            no_orthogonality=NO_ORTHOGONALITY,
        )  # fmt: skip
        object.__setattr__(self, "info", info)
        sched = full.schedule
        object.__setattr__(self, "schedule", sched._replace(**{k: getattr(sched, k)[first:] for k in
                                                               ("prior_cov", "posterior_cov", "gain", "innovation_cov", "transitions")}))  # fmt: skip

    @property
    def _n(self) -> int:
        return self.full.truth.n_updates

    @property
    def truth(self):
        """The truth of the full run (its noise law; ``measurement_dof`` 0)."""
        return self.full.truth

    @property
    def engines(self) -> tuple[str, ...]:
        return self.full.engines

    def has_exact_analysis(self) -> bool:
        return True

    def steady_state_reason(self) -> str:
        return self.steady_reason

    def normals_per_realization(self, engine: str) -> int:
        return self.full.normals_per_realization(engine)

    def run_block(self, rng: np.random.Generator, n: int, engine: str) -> BlockResult:
        block, first = self.full.run_block(rng, n, engine), self.first
        # every field is (n, K, ...) but the sum of P_k over the block, (K, d, d)
        return BlockResult(**{name: None if value is None else (value[first:] if name == "filter_cov_sum" else value[:, first:])
                              for name, value in block._asdict().items()})  # fmt: skip

    def block_sums(self, rng: np.random.Generator, n: int, engine: str) -> MomentSums:
        sums = self.full.block_sums(rng, n, engine)
        return window_sums(sums, self.first, self._n, self.full.filter_model.measurement_dim)

    def expected_mean_error(self) -> np.ndarray:
        return self.full.expected_mean_error()[self.first :]

    def shown_realization(self, rng: np.random.Generator, n: int, index: int, engine: str):
        error, estimate, cov = self.full.shown_realization(rng, n, index, engine)
        return error[self.first :], estimate[self.first :], cov[self.first :]

    def window_analysis(self, analysis):
        """The full run's :class:`~kalcal.analysis.fixed_gain.CovarianceAnalysis` over the reported updates."""
        from kalcal.core.budget import BudgetTerm

        first, n_updates = self.first, self._n
        m = analysis.moments
        moments = dataclasses.replace(
            m, **{f.name: _window(getattr(m, f.name), first, n_updates) for f in dataclasses.fields(m) if f.name != "residual_second_moment"},
            residual_second_moment=None if m.residual_second_moment is None else m.residual_second_moment[first:, :, first:],
        )  # fmt: skip
        budget = tuple(BudgetTerm(t.source, t.kind, t.error_cov[first:]) for t in analysis.budget)
        return dataclasses.replace(
            analysis, info=self.info, moments=moments, filter_cov=analysis.filter_cov[first:],
            innovation_cov=analysis.innovation_cov[first:], mean_nees=analysis.mean_nees[first:],
            mean_nis=analysis.mean_nis[first:], budget=budget,
        )  # fmt: skip


@dataclass(frozen=True)
class DiffuseLoggedGainProblem(LoggedGainProblem):
    """:class:`~kalcal.scenarios.model_file.logged.LoggedGainProblem` whose filter starts diffuse: the
    exact diffuse gains over the log's rows until the prior is proper, then the ordinary pass over the
    log's per-update matrices (module docstring); ``first`` as :class:`DiffuseFixedGainProblem`'s."""

    diffuse: np.ndarray | None = None
    first: int = field(init=False, default=0)

    def __post_init__(self) -> None:
        filt = self.filter_model
        d, p = filt.state_dim, filt.measurement_dim
        if (self.truth.error_dim, self.truth.h.shape[-2]) != (d, p):
            raise ValueError(f"truth: expected {d} filter states and {p} measurements")
        schedule, first, cov = diffuse_schedule(filt.transitions, filt.process_cov, filt.h, filt.v, filt.m0, self.diffuse)
        object.__setattr__(self, "first", first)
        n_updates = filt.transitions.shape[0]
        if first < n_updates:
            rest = dataclasses.replace(
                filt, transitions=filt.transitions[first:], process_cov=filt.process_cov[first:], h=filt.h[first:],
                v=filt.v[first:], m0=cov, steps=filt.steps[first:],
            )  # fmt: skip
            tail = covariance_pass_over(rest, self.form)
            schedule = complete_schedule(schedule, first, tail, tail.phi_interval, tail.q_interval)
        self._adopt(schedule)


def diffuse_logged_problem(scenario, info: ProblemInfo, arrays, form: UpdateForm, residual_pairs: bool):
    """The diffuse filter over a log's rows (the arrays of :func:`kalcal.scenarios.model_file.logged.logged_arrays`),
    run over every update row and checked from the end of the diffuse period on."""
    why = truth_prior_refusal(scenario)
    if why:
        raise ConfigError(f"{scenario.model.file}: {why}")
    flags = diffuse_flags(scenario)
    filt = dataclasses.replace(arrays.filter, x0=np.where(flags, 0.0, arrays.filter.x0))
    full = DiffuseLoggedGainProblem(info=info, filter_model=filt, truth=arrays.truth, form=form, residual_pairs=residual_pairs, diffuse=flags)
    return windowed(scenario, full, full.steady_state_reason(), filt)


def windowed(scenario, full, steady_reason: str, filter_model) -> Any:
    """``full`` reported from its first proper update on (:class:`CheckedWindowProblem`), ``full`` itself
    where the diffuse period ends before the first update; refused in one line where it never ends."""
    n_updates = full.truth.n_updates
    refuse_never_ending(scenario, full.first, n_updates)
    return CheckedWindowProblem(full, full.first, filter_model, steady_reason) if full.first > 0 else full
