"""A nonlinear model's filter against its truth as a verification problem (the engine's Problem protocol).

Each block of n realizations draws, from the block's generator, x_0 ~ N(x0, P0) as (n, d) normals, then
the noises of every update at once as (K, n, q + r) normals: per update and realization the q normals of
the columns of the truth's process-noise factor C_Q (C_Q C_Q^T = Q) that are not all zero, in order,
then the r of the measurement-noise factor C_R's (:func:`_drawn_factor`; imu-3axis: q = 2 of d = 11, its
pose's renewed tilts, and r = p = 3), so that no normal is drawn only to be multiplied by zero. The
compiled kernel takes the same draws in the same order, so a given seed gives the same realizations on
both paths, and whatever the workers (one call of f and h per update for the whole block). The filter (EKF, IEKF or
UKF, :func:`kalcal.core.nonlinear_run.run_nonlinear_filter`) runs on the whole block; as each update ends
its errors, each realization's own P_k and S_k, NEES, NIS and the whitened errors and innovations are
added into the block's sums, with the effect
sizes' sums (:mod:`kalcal.stats.effects`) and the Cramér–Rao bound's expectations at the true states.
Memory is flat in N (a block of n realizations at a time, its sums merged as it ends) but not in K: per
block the draws (K, n, q + r) (and, on the numpy path, the truth's states (K, n, d) and measurements
(n, K, p)), and per run the sums, which grow with K: the residual pair sums as (K p)^2.

**Hooks** for a scenario built on this problem (:class:`ProblemHooks`, the scenario's ``problem_hooks``;
a static-pose calibration uses them): the states the checks are on (the others are nuisance: a pose's tilts),
the states the truth renews at every update (their Cramér–Rao bound is marginalized, update by update),
and a batch estimator that gives one final estimate per realization in place of the filter (its checks
are the final-time ones, :func:`kalcal.stats.suite.final_time_checks`).
"""

from __future__ import annotations

import dataclasses
import functools
import threading
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from kalcal.core.nonlinear_run import NonlinearRun, run_nonlinear_filter
from kalcal.core.ukf import UnscentedSettings
from kalcal.montecarlo.accumulators import BlockResult, MomentSums, SumBuffers, shape_histogram, whiten
from kalcal.montecarlo.problem import ProblemDefaults, ProblemInfo, check_engine
from kalcal.scenarios.nonlinear.settings import COMPILED_MODES as SETTINGS_COMPILED_MODES
from kalcal.stats.effects import EffectAccumulator, EffectLayout


def _factor(cov: np.ndarray) -> np.ndarray:
    """A square root C C^T = cov of a positive semidefinite covariance (Cholesky, or by eigenvalues where
    it is singular: a zero Q of static parameters)."""
    try:
        return np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        w, v = np.linalg.eigh(cov)
        return v * np.sqrt(np.clip(w, 0.0, None))


def _drawn_factor(cov: np.ndarray) -> np.ndarray:
    """The columns of the square root C (:func:`_factor`) that are not all zero, in order: (size, q).

    Each realization and update draws one standard normal per column of the truth's Q and R factors that
    it returns, so that no normal is drawn only to be multiplied by zeros: C w over the dropped columns
    is an exact zero. A singular Q (static parameters kept, a pose's tilts renewed: imu-3axis's Q has
    rank 2 of 11) draws one normal per column its factor keeps (the rank's, or more where an eigenvalue is
    tiny but not zero); a covariance of full rank (a Cholesky factor) draws all."""
    factor = _factor(cov)
    return np.ascontiguousarray(factor[:, np.any(factor != 0.0, axis=0)])


#: the run length, N K (realization-updates), from which ``filter.compiled=auto`` compiles a kernel that
#: is not compiled yet: the compile, about a minute per pair of models (40-80 s measured), against the
#: time the compiled kernel saves over the batched numpy path with every statistic, about 2.2 us per
#: realization-update (2.5 us against 0.24 us for a whole block, range-bearing, K = 100:
#: ``benchmarks/bench_nonlinear.py paths``). One run of 10^7 saves about 22 s, a third of the compile;
#: the compile is kept (numba's cache), so the model's later runs start compiled, and about three runs
#: of that length repay it (one run alone from 2.7 x 10^7). 10^7 is 10^5 realizations of 100 updates
#: (the default 300,000 realizations of 100 updates compile; 10^4 of them run on the numpy path)
COMPILE_WORTH = 10_000_000

#: ``filter.compiled``: ``auto`` (compiled where it is already, or where the run repays its compile),
#: ``yes`` (compile it, for any run), ``no`` (the batched numpy path)
COMPILED_MODES = SETTINGS_COMPILED_MODES

#: realizations per tile of the compiled kernel: the kernel's many short loops over the lanes each pay a
#: fixed cost (their runtime overlap checks) that a longer run spreads, while a tile's arrays stay small
#: (a (d, d, 216) array is 209 KB at d = 11, 28 KB at d = 4). Not a power of two: 128 and 256
#: lanes measured slower than 192-216 and 320 (the likely cause, not measured apart: rows of 2^k floats
#: put the same entries of a tile's arrays a multiple of 4 KB apart, and a load from such an address waits
#: on the store before it, 4K aliasing). Measured on imu-3axis's kernel (benchmarks/README.md, section
#: bench_imu_3axis).
_TILE = 216


#: each thread's arena of the compiled kernel (:func:`_thread_arena`)
_THREAD = threading.local()


def _thread_arena(size: int) -> np.ndarray:
    """This thread's float64 arena of at least ``size`` values for the compiled kernel's tile state
    (:func:`kalcal.scenarios.nonlinear.kernel.arena_size`), kept from block to block and grown as needed.

    A tile's state is 0.51 MB at imu-3axis's d = 11 (its P_{k-1} and P_k, 209 KB each at 216 realizations); memory
    fresh from the system costs a page fault at the first touch of each 4 KB page, and when the kernel held
    a whole block's state (10 MB) that cost 5-6 ms of a 23 ms block. The kernel overwrites what it reads,
    so one arena serves every block of the thread (the engine's threads run one block at a time each);
    it is freed with the thread."""
    arena = getattr(_THREAD, "arena", None)
    if arena is None or arena.shape[0] < size:
        arena = _THREAD.arena = np.empty(size)
    return arena


def _q_inverse(q: np.ndarray) -> tuple[np.ndarray, bool]:
    """Q^-1 of the truth's Q (d x d, once per block: the bound's E[F^T Q^-1 F]) where Q has full rank, by a
    solve against the identity; zeros and False where it is singular (no such expectation)."""
    q = np.asarray(q, dtype=float)
    d = q.shape[0]
    if np.linalg.matrix_rank(q) == d:
        return np.linalg.solve(q, np.eye(d)), True
    return np.zeros((d, d)), False


def _known_rows(name: str, value, size: int, k_count: int, source: str, field_name: str) -> np.ndarray | None:
    """u or data as (size,) shared by every update or (K', size) with K' >= K rows, or None where the model
    takes none: the model's own check of its shape (:func:`kalcal.core.nonlinear._known`), then one row per
    update; a ConfigError naming the field and the shape otherwise."""
    from kalcal.core.nonlinear import _known
    from kalcal.errors import ConfigError

    try:
        array = _known(name, value, size)
    except ConfigError as error:
        raise ConfigError(f"{source}: {field_name}: {error}") from None
    if array is not None and array.ndim == 2 and array.shape[0] < k_count:
        raise ConfigError(
            f"{source}: {field_name}: {name}: {k_count} updates need {k_count} rows of {size} (or one row shared by "
            f"every update), got shape {array.shape}")
    return array


def _check_truth_finite(value: np.ndarray, name: str, k: int, source: str, states: np.ndarray | None = None) -> None:
    """A ConfigError naming the function, the update and a state where the truth's f or h (its output
    ``value``, (n, size)) is NaN or infinite."""
    bad = ~np.all(np.isfinite(value), axis=1)
    if np.any(bad):
        from kalcal.errors import ConfigError

        at = "" if states is None else f", e.g. at x = {np.array2string(states[np.argmax(bad)], precision=4)}"
        raise ConfigError(
            f"{source}: the truth's {name} is not finite (NaN or inf) at update {k + 1} for {int(bad.sum())} of "
            f"{bad.size} realizations{at}: {name} must be finite wherever the truth goes")


def _per_update(value: np.ndarray | None, k: int) -> np.ndarray | None:
    """Update k's row of a shared (size,) or per-update (K, size) array."""
    if value is None:
        return None
    return value if value.ndim == 1 else value[k]


class PathTally:
    """How many blocks of a problem ran on each path in this process, counted as each block ends: ``compiled``
    (the kernel gave the sums), ``fallback`` (the kernel was asked and stopped: a missing measurement or a
    covariance that is not positive definite, and the numpy path gave the sums from the same draws) and
    ``numpy`` (the numpy path was the path). What a run or a benchmark reports as the path that ran, where
    :attr:`NonlinearProblem.compiled_path` says only the path asked for. Blocks run in another process (a
    Dask worker) count in that process's copy: a copy starts at zero."""

    def __init__(self) -> None:
        self._lock = threading.Lock()  # blocks end in several threads at once
        self.compiled = self.fallback = self.numpy = 0

    def add(self, path: str) -> None:
        with self._lock:
            setattr(self, path, getattr(self, path) + 1)

    def __reduce__(self):  # a lock does not pickle; a copy in another process counts its own blocks
        return PathTally, ()

    def describe(self) -> str:
        """One line: the blocks by path, e.g. ``compiled EKF kernel (25 blocks)``."""
        parts = [
            f"{label} ({count} block{'s' if count != 1 else ''})"
            for label, count in (("compiled EKF kernel", self.compiled),
                                 ("numpy path after the kernel stopped", self.fallback),
                                 ("batched numpy path", self.numpy))
            if count
        ]
        return ", ".join(parts) if parts else "no block run"


@dataclass(frozen=True)
class BatchEstimator:
    """One final estimate per realization in place of a filter: ``estimate(z)`` takes the block's
    measurements z (n, K, p) and returns its x (n, d) and cov (n, d, d) in the checked states' order, and a
    residual r (n, q) with its covariance S (n, q, q) under the estimator's own model (the NIS check's)."""

    estimate: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]
    residual_names: tuple[str, ...]
    residual_units: tuple[str, ...]
    #: an iterative estimator's tally, (realizations that did not converge, realizations) per call of
    #: ``estimate`` in this process (the threads' backend; a Dask worker's processes keep their own); None:
    #: not iterative
    convergence: list | None = None


@dataclass(frozen=True)
class ProblemHooks:
    """What a scenario built on :class:`NonlinearProblem` changes in it (all optional).

    Attributes
    ----------
    label : str or None
        The problem's name (``info.scenario``), where not ``nonlinear (KIND, FILE)``.
    checked : tuple of int or None
        The states the checks, effect sizes and bound are on (None: all); the others are nuisance states.
    renewed : tuple of int
        The truth's states renewed at every update (:func:`kalcal.stats.effects.cramer_rao_bound`).
    batch : BatchEstimator or None
        The estimator in place of the filter: one final estimate per realization, checked at the final time.
    """

    label: str | None = None
    checked: tuple[int, ...] | None = None
    renewed: tuple[int, ...] = ()
    batch: BatchEstimator | None = None


class _Batched:
    """One batch estimate as the filter's per-update result (the fields ``on_update`` reads)."""

    def __init__(self, x, cov, residual, innovation_cov):
        self.x, self.cov, self.residual, self.innovation_cov = x, cov, residual, innovation_cov


@dataclass(frozen=True)
class NonlinearProblem(ProblemDefaults):
    """The scenario's filter against its truth (engine "exact": the truth at the update times)."""

    scenario: Any  #: a NonlinearScenario, or a scenario with its attributes and ``problem_hooks``
    residual_pairs: bool = True
    #: whether an EKF's blocks run in the compiled kernel where the models allow it (:attr:`compiled_path`):
    #: one of :data:`COMPILED_MODES` (``no``: the batched numpy path, the oracle the compiled one is held to)
    compiled: str = "auto"
    #: the realizations the runs ahead make of this problem (:meth:`plan`), for ``auto``'s decision; None:
    #: not told (``auto`` then compiles nothing: it runs the kernel only where it is compiled already)
    planned: int | None = None
    info: ProblemInfo = field(init=False)
    engines: tuple[str, ...] = field(init=False, default=("exact",))
    #: the blocks this problem ran by path (:class:`PathTally`); a copy (:meth:`plan`) counts its own
    tally: PathTally = field(init=False, repr=False, compare=False)

    NOT_TIME_INVARIANT = "its model is nonlinear: the gains depend on the state, and there is no algebraic Riccati equation"

    def steady_state_reason(self) -> str:
        """Its gains depend on the state (:attr:`NOT_TIME_INVARIANT`)."""
        return self.NOT_TIME_INVARIANT

    def __post_init__(self) -> None:
        if self.compiled not in COMPILED_MODES:
            raise ValueError(f"filter.compiled: one of {', '.join(COMPILED_MODES)}, got {self.compiled!r}")
        s = self.scenario
        m = s.loaded.filter
        hooks = self.hooks
        names, units = self._checked(np.asarray(m.state_names)), self._checked(np.asarray(m.state_units))
        times = np.arange(1, s.n_updates + 1) * float(m.dt)
        if hooks.batch is not None:  # one final estimate: one reported update, at the last one's time
            times = times[-1:]
        info = ProblemInfo(
            scenario=hooks.label or f"nonlinear ({s.filter.kind}, {s.model.file})",
            update_times=times,
            state_names=tuple(str(v) for v in names),
            state_units=tuple(str(v) for v in units),
            measurement_names=hooks.batch.residual_names if hooks.batch is not None else m.measurement_names,
            measurement_units=hooks.batch.residual_units if hooks.batch is not None else m.measurement_units,
            # a batch estimator's checks are the final-time ones: the capability follows the estimator
            capabilities=dataclasses.replace(s.capabilities, batch=hooks.batch is not None),
        )
        object.__setattr__(self, "info", info)
        object.__setattr__(self, "tally", PathTally())

    @property
    def hooks(self) -> ProblemHooks:
        return getattr(self.scenario, "problem_hooks", None) or ProblemHooks()

    def _checked(self, value: np.ndarray, axes: int = 1) -> np.ndarray:
        """The checked states of a state array's last ``axes`` axes (all of it without the hook)."""
        idx = self.hooks.checked
        if idx is None:
            return value
        idx = np.asarray(idx)
        if axes == 1:
            return value[..., idx]
        return value[..., idx[:, None], idx]

    @property
    def reported_updates(self) -> int:
        return len(self.info.update_times)

    @property
    def layout(self) -> EffectLayout:
        m = self.scenario.loaded.filter
        return EffectLayout(
            self.reported_updates, len(self.info.state_names), len(self.info.measurement_names),
            truth_updates=self.scenario.n_updates, truth_d=m.state_dim,
        )

    def normals_per_realization(self, engine: str) -> int:
        m = self.scenario.loaded.truth
        return m.state_dim + self.scenario.n_updates * (_drawn_factor(m.q).shape[1] + _drawn_factor(m.r).shape[1])

    def expected_mean_error(self) -> np.ndarray:
        """Zeros: no deterministic model error is predicted for a model written as code."""
        return np.zeros((self.reported_updates, len(self.info.state_names)))

    # -- the truth ---------------------------------------------------------------------------------

    def _simulate(self, rng: np.random.Generator, n: int):
        """The block's true states (K, n, d) and measurements (n, K, p), and x_0 (n, d)."""
        loaded = self.scenario.loaded
        t = loaded.truth
        d, p, k_count = t.state_dim, t.measurement_dim, self.scenario.n_updates
        for m in {id(t): t, id(loaded.filter): loaded.filter}.values():  # the checks the compiled path makes
            _known_rows("u", loaded.inputs, m.input_dim, k_count, loaded.source, "INPUTS")
            _known_rows("data", loaded.data, m.data_dim, k_count, loaded.source, "DATA")
        x = t.x0 + rng.standard_normal((n, d)) @ _factor(t.p0).T
        q_factor, r_factor = _drawn_factor(t.q), _drawn_factor(t.r)
        nq = q_factor.shape[1]
        noise = rng.standard_normal((k_count, n, nq + r_factor.shape[1]))
        states = np.empty((k_count, n, d))
        z = np.empty((n, k_count, p))
        x0 = x
        for k in range(k_count):
            # the truth's f and h must be finite wherever the truth goes: a NaN there is the model's error,
            # not a missing measurement (the filter's rule for a NaN in z), and is refused in one line
            # (numpy's warnings of the same NaN held back: the refusal names it)
            with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
                x = t.transition(x, _per_update(loaded.inputs, k)) + noise[k, :, :nq] @ q_factor.T
                _check_truth_finite(x, "f", k, loaded.source)
                states[k] = x
                hx = t.measure(x, _per_update(loaded.data, k))
            _check_truth_finite(hx, "h", k, loaded.source, x)
            z[:, k] = hx + noise[k, :, nq:] @ r_factor.T
        return x0, states, z

    def _run(self, z: np.ndarray, on_update, keep: bool):
        s, loaded = self.scenario, self.scenario.loaded
        f = s.filter
        k_count = s.n_updates
        batch = self.hooks.batch
        if batch is not None:
            result = _Batched(*batch.estimate(z))
            if on_update is not None:
                on_update(0, result)
            if not keep:
                return None
            return NonlinearRun(result.x[:, None], result.cov[:, None], result.residual[:, None], result.innovation_cov[:, None])

        def rows(value):
            if value is None:
                return None
            return np.broadcast_to(value, (k_count, value.shape[-1])) if value.ndim == 1 else value

        return run_nonlinear_filter(
            loaded.filter, z, method=f.kind, u=rows(loaded.inputs), data=rows(loaded.data),
            unscented=UnscentedSettings(f.alpha, f.beta, f.kappa), max_iterations=f.max_iterations,
            on_update=on_update, keep=keep,
        )

    # -- the engine's protocol ----------------------------------------------------------------------

    def run_block(self, rng: np.random.Generator, n: int, engine: str) -> BlockResult:
        """The block's realizations filtered and kept whole (n, K, ...): the numpy oracle of :meth:`block_sums`."""
        check_engine(self, engine)
        _, states, z = self._simulate(rng, n)
        run = self._reported(self._run(z, None, True))
        error = self._checked(self._true_reported(states)).transpose(1, 0, 2) - run.x
        eps = whiten(run.cov, error)
        u = whiten(run.innovation_cov, run.residual)
        return BlockResult(
            error=error,
            estimate=run.x,
            residual=run.residual,
            nees=np.einsum("nki,nki->nk", eps, eps),
            nis=np.einsum("nka,nka->nk", u, u),
            filter_cov_sum=run.cov.sum(axis=0),
            filter_cov=run.cov,
            normalized_residual=u,
        )

    def shown_realization(self, rng: np.random.Generator, n: int, index: int, engine: str = "exact"):
        """Realization ``index`` of a block of n: its error, estimate (K, d) and own P_k (K, d, d)."""
        if not 0 <= index < n:
            raise ValueError(f"realization index must lie in [0, {n}), got {index}")
        check_engine(self, engine)
        _, states, z = self._simulate(rng, n)
        one = slice(index, index + 1)
        run = self._reported(self._run(z[one], None, True))
        return self._checked(self._true_reported(states))[:, index] - run.x[0], run.x[0], run.cov[0]

    def _true_reported(self, states: np.ndarray) -> np.ndarray:
        """The true states (K', n, d) at the reported updates: all K, or the last for a batch estimator."""
        return states[-1:] if self.hooks.batch is not None else states

    def _reported(self, run: NonlinearRun) -> NonlinearRun:
        """A run's checked states (the filter's own order; a batch estimator's are already so)."""
        if self.hooks.batch is not None or self.hooks.checked is None:
            return run
        return NonlinearRun(self._checked(run.x), self._checked(run.cov, 2), run.residual, run.innovation_cov)

    def plan(self, n_total: int) -> NonlinearProblem:
        """The problem as it runs the ``n_total`` realizations its caller is about to run (the Problem
        protocol's; one run's N, or R runs' R N): what ``filter.compiled=auto`` weighs a compile against.
        A plan only grows (the larger of this one and an earlier one), so that an inner caller's run of
        part of the work keeps the outer caller's decision."""
        total = max(int(n_total), self.planned or 0)
        return self if total == self.planned else dataclasses.replace(self, planned=total)

    @property
    def compiled_path(self) -> tuple[bool, str]:
        """Whether :meth:`block_sums` runs the compiled EKF kernel, and why not where it does not.

        The compiled path (:mod:`kalcal.scenarios.nonlinear.kernel`) runs an EKF of models whose f and h
        sympy can take (the default Jacobians), its checks on the hooks' checked states where a scenario
        sets them (imu-3axis: the 9 parameters of 11 states); the IEKF and the UKF, a batch estimator, and
        models with explicit numpy Jacobians, jax's or finite differences, run the batched numpy path. Of the models it takes, the
        ``compiled`` setting decides: ``yes`` compiles the kernel (about a minute per pair of models, once:
        numba caches it), ``no`` keeps the numpy path, and ``auto`` (the default) runs the kernel where it is
        compiled already (in this process or in numba's cache) or where the planned run, N K realization-
        updates (:meth:`plan`), is at least :data:`COMPILE_WORTH` (its compile repaid), else the numpy path.
        """
        if self.compiled == "no":
            return False, "the numpy path was asked for (filter.compiled=no)"
        if self.hooks.batch is not None:
            return False, "a batch estimator (one final estimate per realization) runs on the batched numpy path"
        kind = self.scenario.filter.kind
        if kind != "ekf":
            return False, f"the {kind.upper()} runs on the batched numpy path (only the EKF is compiled)"
        from kalcal.scenarios.nonlinear.compiled import block_kernel, is_compiled

        loaded = self.scenario.loaded
        kernel, reason = block_kernel(loaded.truth, loaded.filter)
        if kernel is None:
            return False, reason
        if self.compiled == "yes" or is_compiled(kernel):
            return True, ""
        work = (self.planned or 0) * self.scenario.n_updates
        if work >= COMPILE_WORTH:
            return True, ""
        planned = "a run of untold length" if not self.planned else (
            f"{self.planned} realizations of {self.scenario.n_updates} updates ({work:.3g} realization-updates)")
        return False, (
            f"filter.compiled=auto: the EKF kernel of these models is not compiled yet, and {planned} is below the "
            f"{COMPILE_WORTH:.0e} that repay its compile (about a minute); filter.compiled=yes compiles it"
        )

    def block_sums(self, rng: np.random.Generator, n: int, engine: str) -> MomentSums:
        """The moment sums and the effect sums of n realizations: the compiled EKF kernel where
        :attr:`compiled_path` allows (the same draws, the same sums to rounding), else :meth:`numpy_block_sums`."""
        check_engine(self, engine)
        if self.compiled_path[0]:
            state = rng.bit_generator.state
            out = self._compiled_block_sums(rng, n)
            if out is not None:
                self.tally.add("compiled")
                return out
            # a missing measurement or a covariance that is not positive definite: the numpy path gives
            # that case's numbers (or its error) from the same draws
            rng.bit_generator.state = state
            out = self.numpy_block_sums(rng, n, engine)
            self.tally.add("fallback")
            return out
        out = self.numpy_block_sums(rng, n, engine)
        self.tally.add("numpy")
        return out

    @functools.cached_property
    def _kernel_inputs(self) -> tuple:
        """What the compiled kernel takes that depends on the models alone, derived once per problem (not
        once per block: the factors, Q's rank, the effect layout's views and the input rows cost about
        1 ms of Python a block): the checked states, the truth's drawn factors of Q and R, its P0 factor,
        Q^-1 and whether Q has full rank, R's Cholesky factor, the inputs' and data's rows (K, size), the
        effect layout and the names of its views in the kernel's order. The problem is frozen and its
        models are immutable, so the values stay valid (a problem of other models is another instance)."""
        s, loaded = self.scenario, self.scenario.loaded
        t = loaded.truth
        k_count = s.n_updates
        checked = np.arange(t.state_dim) if self.hooks.checked is None else np.asarray(self.hooks.checked, dtype=np.int64)

        def rows(name, value, size):
            # the numpy path's checks (the model's own, then one row per update) before any broadcast
            if size == 0:
                return np.zeros((k_count, 0))
            value = _known_rows(name, value, size, k_count, loaded.source, "DATA" if name == "data" else "INPUTS")
            return np.ascontiguousarray(np.broadcast_to(value, (k_count, size)) if value.ndim == 1 else value[:k_count])

        q_inv, has_q_inv = _q_inverse(t.q)
        layout = self.layout
        names = ("nees_sq", "nees_avg", "nis_avg", "e4", "p2", "e2p", "pooled", "z", "z2", "zbar", "lag1", "f", "ftqf", "htrh")
        return (checked, _drawn_factor(t.q), _drawn_factor(t.r), _factor(t.p0), q_inv, has_q_inv, np.linalg.cholesky(t.r),
                rows("u", loaded.inputs, t.input_dim), rows("data", loaded.data, t.data_dim), layout,
                tuple(layout.slices[name] for name in names))

    def _compiled_block_sums(self, rng: np.random.Generator, n: int) -> MomentSums | None:
        s, loaded = self.scenario, self.scenario.loaded
        t, fm = loaded.truth, loaded.filter
        d, p, k_count = t.state_dim, t.measurement_dim, s.n_updates
        checked, q_factor, r_factor, p0_factor, q_inv, has_q_inv, r_chol, u_rows, data_rows, layout, views = self._kernel_inputs
        # the numpy path's draws, in its order (_simulate)
        first = rng.standard_normal((n, d))
        noise = rng.standard_normal((k_count, n, q_factor.shape[1] + r_factor.shape[1]))
        # the checks' sums on the checked states (layout.d of them), the bound's on the truth's d
        sums = SumBuffers.zeros(k_count, layout.d, p, n, self.residual_pairs, own_cov=True)
        flat = layout.zeros()
        eff = tuple(flat[where].reshape(shape) for where, shape in views)
        normalized = np.zeros((k_count, p))

        if t.input_dim != fm.input_dim or t.data_dim != fm.data_dim:
            return None

        from kalcal.scenarios.nonlinear.compiled import run_block
        from kalcal.scenarios.nonlinear.kernel import arena_size

        ok = run_block(
            t, fm,
            first, noise, t.x0, p0_factor, q_factor, r_factor, float(t.dt),
            q_inv, has_q_inv, r_chol,
            fm.x0, fm.p0, fm.q, fm.r, float(fm.dt),
            u_rows, data_rows, checked, sums, normalized, eff, _TILE,
            _thread_arena(arena_size(d, p, checked.shape[0], _TILE)),
        )
        if not ok:
            return None
        return MomentSums.from_buffers(n, sums, normalized_residual=normalized).with_effect(flat)

    def numpy_block_sums(self, rng: np.random.Generator, n: int, engine: str = "exact") -> MomentSums:
        """The moment sums and the effect sums of n realizations by the batched numpy filter, update by
        update: the oracle of the compiled kernel, and the path of the models and filters it does not take."""
        check_engine(self, engine)
        s, loaded = self.scenario, self.scenario.loaded
        t = loaded.truth
        d_truth, k_truth = t.state_dim, s.n_updates
        layout = self.layout
        d, p, k_count = layout.d, layout.p, layout.n_updates
        x0, states, z = self._simulate(rng, n)
        sums = SumBuffers.zeros(k_count, d, p, n, self.residual_pairs, own_cov=True)
        flat = layout.zeros()
        effects = EffectAccumulator(layout, flat, n)
        normalized = np.zeros((k_count, p))
        q_inv, has_q_inv = _q_inverse(t.q)
        r_chol = np.linalg.cholesky(t.r)
        reported = self._true_reported(states)
        batch = self.hooks.batch is not None

        def on_update(k: int, result) -> None:
            x_true = self._checked(reported[k])
            x_hat = result.x if batch else self._checked(result.x)
            cov = result.cov if batch else self._checked(result.cov, 2)
            result = _Batched(x_hat, cov, result.residual, result.innovation_cov)
            e = x_true - result.x
            eps = whiten(cov, e)
            u = whiten(result.innovation_cov, result.residual)
            nees_k = np.einsum("ni,ni->n", eps, eps)
            nis_k = np.einsum("na,na->n", u, u)
            sums.error[k] += e.sum(0)
            sums.error_outer[k] += e.T @ e
            sums.estimate[k] += result.x.sum(0)
            sums.estimate_outer[k] += result.x.T @ result.x
            sums.error_estimate[k] += e.T @ result.x
            sums.nees[k] += nees_k.sum()
            sums.nis[k] += nis_k.sum()
            sums.residual[k] += result.residual.sum(0)
            sums.residual_own[k] += result.residual.T @ result.residual
            sums.filter_cov[k] += cov.sum(0)
            sums.whitened_error[k] += eps.sum(0)
            sums.whitened_outer[k] += eps.T @ eps
            sums.whitened_estimate[k] += eps.T @ result.x
            normalized[k] += u.sum(0)
            # the shape check's histograms: this update's NEES (chi-square(d), d the checked states) and NIS
            # (chi-square(p), p the filter's measurements or the batch estimator's residuals) binned
            sums.nees_histogram[k] += shape_histogram(nees_k[:, None], d)[0]
            sums.nis_histogram[k] += shape_histogram(nis_k[:, None], p)[0]
            if self.residual_pairs:
                sums.residuals[k * p:(k + 1) * p] = u.T
            effects.update(k, e, cov, nees_k, nis_k, u)

        self._run(z, on_update, False)
        # the Cramér–Rao bound's expectations, at the truth's own states with the truth's Jacobians, at
        # every update of the truth (a batch estimator's one reported update included all of them)
        for k in range(k_truth):
            previous = x0 if k == 0 else states[k - 1]
            jf = t.transition_jacobian(previous, _per_update(loaded.inputs, k))
            jh = t.measurement_jacobian(states[k], _per_update(loaded.data, k))
            wh = np.linalg.solve(r_chol, jh)  # R^-1/2 H, (n, p, d): a triangular solve, no inverse
            ftqf = np.einsum("nai,ab,nbj->ij", jf, q_inv, jf) if has_q_inv else np.zeros((d_truth, d_truth))
            effects.truth(k, jf.sum(0), ftqf, np.einsum("nai,naj->ij", wh, wh))
        effects.finish()
        return MomentSums.from_buffers(n, sums, normalized_residual=normalized).with_effect(flat)

    def simulated_power(self, n: int, seed: int, confidence: float, workers: int | None = None):
        """The checks' power by simulation against the named alternatives (``checks.power_runs`` runs each,
        :mod:`kalcal.scenarios.nonlinear.power`); None where the setting is 0."""
        runs = self.scenario.checks.power_runs
        if not runs:
            return None
        from kalcal.scenarios.nonlinear.power import simulated_power

        return simulated_power(self.scenario, n, seed, confidence, runs, workers)

    def effect_sizes(self, sums: MomentSums, confidence: float):
        """The run's effect sizes, tolerance verdicts (``checks.tolerance``) and the truth's Cramér–Rao bound."""
        from kalcal.stats.effects import effect_sizes

        t = self.scenario.loaded.truth
        return effect_sizes(
            self.layout, sums.effect, sums, self.info.state_names, confidence, self.scenario.checks.tolerance, (t.q, t.r, t.p0),
            renewed=self.hooks.renewed,
        )
