"""What the Monte Carlo engine verifies: a truth to sample and a filter to run on it.

A problem turns a generator and a count n into a :class:`BlockResult` (the filter's errors, estimates,
innovations and normalized squares for n realizations); the engine does seeding, batching, threads and
merging. :class:`FixedGainProblem` serves every time-invariant linear model whose gains can be computed
ahead of the data (the report's filter); problems with data-dependent gains implement the same protocol.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from kalcal.core.model import LinearGaussianModel
from kalcal.core.steps import GainSchedule, UpdateForm, covariance_pass, nis, summed_nis
from kalcal.errors import ConfigError
from kalcal.filters.gains import run_with_gains
from kalcal.linalg import whitener
from kalcal.montecarlo.accumulators import BlockResult, MomentSums, SumBuffers
from kalcal.simulation.exact import UpdateRateTruth, sample_exact

#: why a fixed-gain problem with a transition per interval has no steady state
VARYING_TRANSITION = (
    "the filter's transition changes from one update interval to the next (a scale-factor state's column "
    "carries the measured acceleration), so the model is not time-invariant and there is no algebraic "
    "Riccati equation"
)

#: the kernel's error map for a truth over the filter's own states (no map: e = x - xhat, no product)
_EMPTY_MAP = np.empty((0, 0))

Sampler = Callable[[np.random.Generator, int], tuple[np.ndarray, np.ndarray]]
#: ``(rng, n, phis, h, gains, x0, sums) -> None``: a compiled sampler fused with the filter and the sums
BlockSums = Callable[..., None]


#: Most filter updates one realization may have, in the run and in its long run (2000: 400 s at the
#: accel-gps default 5 Hz GPS; the default run has 150, the 120 s long run 600). A block of 4096
#: realizations holds its draws and residuals per update (about 0.2 MB per update and thread) and the
#: run keeps E[r_k r_j^T] over every pair of updates, (K p)^2 numbers: 128 MB per copy at K = 2000, p = 2.
#: Beyond it the arrays would not fit a usual machine, so the run is refused before it starts.
MAX_UPDATES = 2000


@dataclass(frozen=True)
class ProblemInfo:
    """Names, units and times that label the statistics."""

    scenario: str
    update_times: np.ndarray  #: s, (K,)
    state_names: tuple[str, ...]
    state_units: tuple[str, ...]
    measurement_names: tuple[str, ...]
    measurement_units: tuple[str, ...]
    #: the capabilities of the scenario it was built from (:class:`~kalcal.scenarios.protocol.Capabilities`):
    #: what the checks, the power and the report ask of it (an exact analysis, the same P in every
    #: realization); None for a problem built by hand, which those then refuse
    capabilities: Any = None
    #: the updates of the run left out of the checks and statistics, in words ("" for none): a diffuse
    #: filter's diffuse period (:mod:`kalcal.scenarios.model_file.diffuse`), whose P and S are infinite
    not_checked: str = ""
    #: why the orthogonality check is left out ("" where it is made): E[e xhat^T] = 0 holds for a posterior
    #: mean, and a diffuse filter's estimate ignores the world's prior (:mod:`kalcal.scenarios.model_file.diffuse`)
    no_orthogonality: str = ""
    #: what the run's reader should know of the model, in words (``summary.json``'s ``notes``): a model file's
    #: known inputs, whose effect on the error the run either cancels or carries (:mod:`kalcal.scenarios.model_file`)
    notes: tuple[str, ...] = ()


def capabilities_of(problem) -> Any:
    """The capabilities of the scenario ``problem`` was built from (its ``info.capabilities``)."""
    caps = problem.info.capabilities
    if caps is None:
        raise TypeError(f"{problem.info.scenario}: a problem built without its scenario's capabilities")
    return caps


class Problem(Protocol):
    """The engine's view of a verification problem."""

    info: ProblemInfo
    engines: tuple[str, ...]

    def run_block(self, rng: np.random.Generator, n: int, engine: str) -> BlockResult:
        """Simulate n realizations with ``engine`` and run the filter on them."""

    def block_sums(self, rng: np.random.Generator, n: int, engine: str) -> MomentSums:
        """The moment sums of ``run_block`` with the same generator (a problem may fuse the two)."""

    def normals_per_realization(self, engine: str) -> int:
        """Standard normals one realization draws (the cost the engine is measured against)."""

    def expected_mean_error(self) -> np.ndarray:
        """E[e_k] implied by the truth's means and deterministic model error, (K, d)."""

    def shown_realization(
        self, rng: np.random.Generator, n: int, index: int, engine: str
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Realization ``index`` of a block of n drawn from ``rng`` with ``engine``, as ``run_block`` draws
        it: its error and estimate (K, d), in the states' units, and the filter's own P_k (K, d, d). What the
        report's realization figures show; each problem takes its cheapest way to it."""

    def has_exact_analysis(self) -> bool:
        """Whether it holds the arrays of an exact covariance analysis (a truth and gains fixed before any
        data: :func:`kalcal.analysis.fixed_gain.analyze_problem`)."""

    def steady_state_reason(self) -> str:
        """Why its filter has no steady state for the report ("" where the DARE applies to its model)."""

    def effect_sizes(self, sums: MomentSums, confidence: float) -> Any:
        """The run's effect sizes and tolerance outcomes (:class:`kalcal.stats.effects.EffectSizes`) from
        its sums, for a nonlinear model's filter (its capabilities' ``nonlinear``); None where it keeps none."""

    def simulated_power(self, n: int, seed: int, confidence: float, workers: int | None = None) -> Any:
        """The checks' power by simulation where its settings ask for it; None for none."""

    def plan(self, n_total: int) -> Problem:
        """The problem as it should run the ``n_total`` realizations its caller is about to run (one run's N,
        or all of a series'): a problem whose fastest path costs a setup (a nonlinear model's compiled
        kernel) weighs it against the run; the problem itself where nothing depends on it."""


#: why a problem whose gains depend on the data has no steady state, where it says nothing more precise
DATA_DEPENDENT_GAINS = "its gains depend on the data, so the filter is not time-invariant"


class ProblemDefaults:
    """The :class:`Problem` protocol's answers for a problem with nothing of its own to say: no exact
    analysis, no steady state where its scenario's gains are not fixed (the generic reason), no effect
    sizes, no power by simulation, no plan. A problem inherits this and overrides what differs."""

    def has_exact_analysis(self) -> bool:
        """False: only a fixed-gain problem holds the arrays."""
        return False

    def steady_state_reason(self) -> str:
        """The generic reason: its gains depend on the data."""
        return DATA_DEPENDENT_GAINS

    def effect_sizes(self, sums: MomentSums, confidence: float) -> None:
        """None: it keeps no effect sums."""
        return None

    def simulated_power(self, n: int, seed: int, confidence: float, workers: int | None = None) -> None:
        """None: no power by simulation."""
        return None

    def plan(self, n_total: int):
        """Itself: its path does not depend on the run's length."""
        return self


def check_engine(problem: Problem, engine: str, option: str = "") -> None:
    """Raise ConfigError (a ValueError), naming the problem's engines, unless ``engine`` is one of
    ``problem.engines``; ``option`` (e.g. ``"--engine"``) leads the message when the value came from one."""
    if engine not in problem.engines:
        lead = f"{option}: " if option else "engine "
        raise ConfigError(f"{lead}{engine!r} is not available for {problem.info.scenario} (have {', '.join(problem.engines)})")


def _inverse_spd(cov: np.ndarray) -> np.ndarray:
    """W^T W for the Cholesky whitener W: the inverse of each symmetric positive definite matrix."""
    w = whitener(cov)
    return np.swapaxes(w, -1, -2) @ w


@dataclass(frozen=True)
class FixedGainProblem(ProblemDefaults):
    """A time-invariant filter with precomputed gains against an update-rate truth.

    Parameters
    ----------
    info : ProblemInfo
    filter_model : LinearGaussianModel
        What the filter believes.
    truth : UpdateRateTruth
        What the world does, sampled exactly at the update rate (engine "exact"). Its states may be
        more than the filter's d: with an ``error_map`` M (d, n) the filter's error is M x - xhat.
    sampled : callable, optional
        ``sampled(rng, n) -> (states (n, K, d), measurements (n, K, p))`` simulating every sample
        (engine "sampled").
    sampled_block : callable, optional
        The same realizations (same draws of ``rng``) simulated, filtered and summed by one compiled
        pass, ``sampled_block(rng, n, phis, h, gains, x0, sums)``, which :meth:`block_sums` then uses
        for engine "sampled" (:func:`kalcal.scenarios.accel_gps.sampled_kernels.accel_gps_block_sums`); without
        it, ``sampled``'s arrays are filtered by :func:`kalcal.montecarlo.kernels.filter_block_moments`.
    form : {"joseph", "standard", "sqrt"}
        The covariance update of the gain schedule (:func:`~kalcal.core.steps.covariance_pass`).
    """

    info: ProblemInfo
    filter_model: LinearGaussianModel
    truth: UpdateRateTruth
    sampled: Sampler | None = None
    sampled_normals: int = 0
    sampled_block: BlockSums | None = None
    form: UpdateForm = "joseph"
    residual_pairs: bool = True  #: keep E[r_k r_j^T] over all pairs (O(N K^2 p^2)) for the whiteness check
    filter_transitions: np.ndarray | None = None  #: the filter's transition of each interval, (K, d, d), if time-varying
    schedule: GainSchedule = field(init=False)
    _state_whitener: np.ndarray = field(init=False, repr=False)
    _innovation_whitener: np.ndarray = field(init=False, repr=False)
    _state_inverse: np.ndarray = field(init=False, repr=False)
    #: the predicted means of the error (K, d) and the innovation (K, p): the shape histograms' centers
    _centers: tuple = field(init=False, repr=False)

    def __post_init__(self) -> None:
        d, p = self.filter_model.state_dim, self.filter_model.measurement_dim
        if (self.truth.error_dim, self.truth.h.shape[0]) != (d, p):
            raise ValueError(
                f"truth: expected {d} filter states and {p} measurements, got {self.truth.error_dim} and {self.truth.h.shape[0]}"
            )
        self._adopt(covariance_pass(self.filter_model, self.truth.n_updates, self.form, self.filter_transitions))

    def _adopt(self, schedule: GainSchedule) -> None:
        """Take ``schedule`` as the problem's gains, with what follows from it: the whiteners of P_k and S_k,
        P_k^{-1} and the shape histograms' centers."""
        object.__setattr__(self, "schedule", schedule)
        object.__setattr__(self, "_state_whitener", whitener(schedule.posterior_cov))
        object.__setattr__(self, "_innovation_whitener", whitener(schedule.innovation_cov))
        # sum_i e_i^T P^{-1} e_i = tr(P^{-1} sum_i e_i e_i^T): the NEES sums from the second moments.
        object.__setattr__(self, "_state_inverse", _inverse_spd(schedule.posterior_cov))
        object.__setattr__(self, "_centers", self._predicted_means())

    @property
    def engines(self) -> tuple[str, ...]:
        return ("exact", "sampled") if self.sampled is not None else ("exact",)

    def has_exact_analysis(self) -> bool:
        """True: its truth and gain schedule are the exact analysis's arrays."""
        return True

    def steady_state_reason(self) -> str:
        """"" for a time-invariant model; why not where its transition changes from interval to interval."""
        return VARYING_TRANSITION if self.filter_transitions is not None else ""

    def normals_per_realization(self, engine: str) -> int:
        return self.truth.normals_per_realization if engine == "exact" else self.sampled_normals

    def sample(self, rng: np.random.Generator, n: int, engine: str) -> tuple[np.ndarray, np.ndarray]:
        """States (n, K, d) and measurements (n, K, p) from the chosen engine."""
        check_engine(self, engine)
        return sample_exact(self.truth, rng, n) if engine == "exact" else self.sampled(rng, n)

    def filter(self, measurements: np.ndarray):
        """The filter's run over measurements (n, K, p)."""
        return run_with_gains(self.schedule, self.filter_model.h, measurements, self.filter_model.x0)

    def run_block(self, rng: np.random.Generator, n: int, engine: str) -> BlockResult:
        states, measurements = self.sample(rng, n, engine)
        run = self.filter(measurements)
        if engine == "exact" and self.truth.error_map is not None:
            states = states @ self.truth.error_map.T  # the filter's states of a truth with its own: M x
        error = states - run.posterior
        whitened_error = np.einsum("kij,nkj->nki", self._state_whitener, error)
        whitened_residual = np.einsum("kij,nkj->nki", self._innovation_whitener, run.residual)
        centered_error = np.einsum("kij,nkj->nki", self._state_whitener, error - self._centers[0])
        centered_residual = np.einsum("kij,nkj->nki", self._innovation_whitener, run.residual - self._centers[1])
        return BlockResult(
            error=error,
            estimate=run.posterior,
            residual=run.residual,
            nees=np.einsum("nki,nki->nk", whitened_error, whitened_error),
            nis=nis(run.residual, self.schedule.innovation_cov),
            filter_cov_sum=n * self.schedule.posterior_cov,
            normalized_residual=whitened_residual,
            filter_cov=np.broadcast_to(self.schedule.posterior_cov, (n, *self.schedule.posterior_cov.shape)),
            shape_nees=np.einsum("nki,nki->nk", centered_error, centered_error),
            shape_nis=np.einsum("nki,nki->nk", centered_residual, centered_residual),
        )

    def _gains(self) -> tuple:
        """The filter's arguments of the compiled kernels: Phi_k (K, d, d), H (p, d), K_k (K, d, p), x0 (d,),
        and the whiteners of P_k (K, d, d) and S_k (K, p, p) and the predicted means of e_k (K, d) and r_k
        (K, p) for each realization's NEES and NIS in the shape histograms."""
        return (
            np.ascontiguousarray(self.schedule.transitions),
            self.filter_model.h,
            self.schedule.gain,
            self.filter_model.x0,
            np.ascontiguousarray(self._state_whitener),
            np.ascontiguousarray(self._innovation_whitener),
            *self._centers,
        )

    def _exact_block(self, rng: np.random.Generator, n: int, sums: SumBuffers, traced: int = -1) -> np.ndarray:
        """The exact engine's compiled block into ``sums``; the error and estimate (2, K, d) of realization
        ``traced`` of the block ((0, 0, 0) for -1)."""
        from kalcal.montecarlo import kernels  # numba: loaded by the runs, not by what only describes a problem

        if not -1 <= traced < n:  # the kernel does not check its indices
            raise ValueError(f"traced realization must lie in [-1, {n}), got {traced}")

        truth = self.truth
        c = int(truth.shares_boundary)
        d0 = truth.x0_factor.shape[1]
        first = rng.standard_normal((d0 + c, n))
        noise = np.column_stack([truth.noise_factor] + ([truth.boundary_out] if c else []))
        trace = np.zeros((2, truth.n_updates, self.filter_model.state_dim) if traced >= 0 else (0, 0, 0))
        # the kernel draws each update's normals from rng as it reaches it (sample_exact's next draw,
        # (K, r + c + p, n), in the same order), so that they are read from the cache, not from memory
        kernels.exact_block_moments(
            truth.x0_mean[:, None] + truth.x0_factor @ first[:d0],
            np.ascontiguousarray(first[d0:]),
            rng,
            np.ascontiguousarray(truth.transitions),
            np.ascontiguousarray(noise),
            np.ascontiguousarray(truth.boundary_in[:, None][:, :c]),
            truth.model_error,
            truth.h,
            truth.measurement_factor,
            *self._gains(),
            sums,
            _EMPTY_MAP if truth.error_map is None else np.ascontiguousarray(truth.error_map),
            traced,
            trace,
            int(truth.measurement_dof),
        )
        return trace

    def traced_realization(self, rng: np.random.Generator, n: int, index: int) -> tuple[np.ndarray, np.ndarray]:
        """Error and estimate (K, d), in the states' units, of realization ``index`` of an exact-engine block
        of n drawn from rng, through the compiled block: its draws and arithmetic, so equal to ``run_block``'s
        to rounding, in a fraction of numpy's time once the kernel is loaded (the block's other
        realizations are drawn and filtered, not kept; ``benchmarks/bench_report.py`` prints both times)."""
        if not 0 <= index < n:
            raise ValueError(f"realization index must lie in [0, {n}), got {index}")
        sums = SumBuffers.zeros(self.truth.n_updates, self.filter_model.state_dim, self.filter_model.measurement_dim, n, False)
        error, estimate = self._exact_block(rng, n, sums, index)
        return error, estimate

    def shown_realization(
        self, rng: np.random.Generator, n: int, index: int, engine: str
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Realization ``index`` of a block of n: error, estimate (K, d) and P_k (K, d, d), the same in
        every realization here. The exact engine runs the block through the compiled kernel
        (:meth:`traced_realization`: ``run_block``'s values to rounding); the sampled engine draws the block
        and filters it through numpy (``run_block``'s values bit for bit, without the statistics the
        figures do not show: whitened errors and innovations, NEES and NIS)."""
        if not 0 <= index < n:
            raise ValueError(f"realization index must lie in [0, {n}), got {index}")
        cov = np.array(self.schedule.posterior_cov)
        if engine == "exact":
            return (*self.traced_realization(rng, n, index), cov)
        states, measurements = self.sample(rng, n, engine)
        run = self.filter(measurements)
        state = states[index]
        return state - run.posterior[index], run.posterior[index], cov

    def block_sums(self, rng: np.random.Generator, n: int, engine: str) -> MomentSums:
        """The moment sums of n realizations through the compiled kernels (same draws as ``run_block``)."""
        from kalcal.montecarlo import kernels  # numba: loaded by the runs, not by what only describes a problem
        n_updates, d, p = self.truth.n_updates, self.filter_model.state_dim, self.filter_model.measurement_dim
        sums = SumBuffers.zeros(n_updates, d, p, n, self.residual_pairs)
        gains = self._gains()
        if engine == "exact":
            self._exact_block(rng, n, sums)
        elif self.sampled_block is not None:
            check_engine(self, engine)
            self.sampled_block(rng, n, *gains, sums)
        else:
            states, measurements = self.sample(rng, n, engine)
            kernels.filter_block_moments(
                np.ascontiguousarray(states.transpose(1, 2, 0)),
                np.ascontiguousarray(measurements.transpose(1, 2, 0)),
                *gains,
                sums,
            )
        # Every realization shares P_k and S_k: sum_i e_i^T P^{-1} e_i = tr(P^{-1} sum_i e_i e_i^T) (the NIS
        # likewise, :func:`summed_nis`), and the whitening is linear, so the sum of L^{-1} r is L^{-1} times
        # the sum of r.
        shared = sums._replace(
            nees=np.einsum("kij,kij->k", self._state_inverse, sums.error_outer),
            nis=summed_nis(sums.residual_own, self.schedule.innovation_cov),
            filter_cov=n * self.schedule.posterior_cov,
        )
        return MomentSums.from_buffers(n, shared, np.einsum("kij,kj->ki", self._innovation_whitener, sums.residual))

    def _predicted_means(self) -> tuple[np.ndarray, np.ndarray]:
        """E[e_k] (K, d) and E[r_k] (K, p) from the truth's mean trajectory (:meth:`expected_mean_error`): the
        shape check tests each realization's NEES and NIS about them, so that a deterministic model error,
        which the mean_error check accounts for, does not make the NEES a noncentral chi-square; zero for a
        truth without one (then nothing is shifted)."""
        mean, run = self._mean_run()
        return np.ascontiguousarray(mean - run.posterior[0]), np.ascontiguousarray(run.residual[0])

    def _mean_run(self):
        """The truth's mean trajectory M E[x_k] (K, d) and the filter's run over its mean measurements
        H E[x_k] (what :meth:`expected_mean_error` and :meth:`_predicted_means` take their means from)."""
        truth = self.truth
        mean = np.empty((truth.n_updates, truth.state_dim))
        y = truth.x0_mean
        for k in range(truth.n_updates):
            y = truth.transitions[k] @ y
            mean[k] = y + truth.model_error[k]
        run = self.filter((mean @ truth.h.T)[None])
        return (mean if truth.error_map is None else mean @ truth.error_map.T), run

    def expected_mean_error(self) -> np.ndarray:
        """The filter's response to the truth's mean trajectory: M E[x_k] - E[xhat_k], (K, d).

        E[x_k] = A^{k+1} x0_mean + D_k (the truth's n states); the filter is linear, so its mean estimate
        is its run on H E[x_k]. M is the truth's ``error_map`` (the identity without one). Nonzero only
        when the truth's prior mean differs from the filter's, the truth carries deterministic model
        error, or (with a map) the truth's mean dynamics differ from the filter's.
        """
        mean, run = self._mean_run()
        return mean - run.posterior[0]
