"""A model file verified over a log (``verify MODEL.toml --data LOG``): the log's rows give the gains, once.

The log says where the filter updates and what it measures there; the Monte Carlo draws the states and
the measurements, so the log's own measured values are never used, only which components are measured.
From the bound model (:func:`kalcal.scenarios.model_file.data.bind`), update k (k = 0..K-1) is the k-th
row j_k with a measured component; between two updates (and from the prior at row 0 to the first)
the model steps s_k = j_k - j_{k-1} rows (j_{-1} = 0, so a measurement at row 0 has s_0 = 0)::

    x_{j_k} = Phi_k x_{j_{k-1}} + noise ~ N(0, Q_k),    Phi_k = Phi^{s_k},
    Q_k = sum_{i<s_k} Phi^i Gamma W Gamma^T (Phi^i)^T         (:func:`kalcal.core.steps.interval_transition`)
    z_k = H_{j_k} x_{j_k} + v_k,   v_k ~ N(0, V_{j_k})         (the rows and stds the log gives)

These are the same in every realization, so the gains K_k are computed once (:func:`covariance_pass`, the
steps of :mod:`kalcal.core.steps`), the exact analysis (:mod:`kalcal.core.lincov`, with per-update H, Q
and R) still applies, and the compiled block kernel
(:func:`kalcal.scenarios.model_file.logged_kernels.logged_block_moments`) samples, filters and sums in one
pass, as the time-invariant one does.

Known inputs. x_{j+1} = Phi_t x_j + B_t u_j + Gamma_t w_j in the truth, xhat_{j+1}^- = Phi xhat_j + B u_j
in the filter's prediction. Where the input moves the truth as the filter believes (M B_t = B,
M Phi_t = Phi M and H_t = H M, M the truth's map or the identity: a truth with no b, phi or h of its
own), the error e = M x - xhat and the innovations do not depend on u
(:func:`kalcal.scenarios.model_file.model._inputs_cancel`): the truth carries no input state, the draws and
the error and innovation sums are those of any u, and the estimates get the filter's own response to the
log's inputs f_k (``estimate_offset``), as below, because the orthogonality check's E[e xhat^T] does depend
on u where the mean error is not zero (a truth whose prior mean is not the filter's). Otherwise the log's u_j, the same in
every realization, give the error and the innovations a deterministic offset at each update, M g_k - f_k
and H_t,k g_k - H_k f_k (g the truth's response to u, f the filter's): :func:`driven_truth` carries g and f
as truth states, so that the kernel, the numpy reference and the exact analysis take the offset
unchanged; the mean-error check then sees the filter's bias, which the exact analysis predicts. The
engine's filter runs without the inputs (its estimates are xhat_k - f_k); :class:`LoggedGainProblem` and
the exact analysis add f_k back to every estimate they keep.

Stated limits, each refused in one line: a measured pattern (which components) that changes from one
update row to another (the fixed-gain engine holds p measurements at every update; a constant pattern
that leaves a component out is verified on the components measured); a log without a measured row. A
filter that starts diffuse takes the exact diffuse gains over the log's rows and is checked from the end of
its diffuse period on (:mod:`kalcal.scenarios.model_file.diffuse`).
"""

from __future__ import annotations

import dataclasses
import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from kalcal.core.sources import Source
from kalcal.core.sqrt_form import cholesky_factor, gram, sqrt_gain_and_factor, sqrt_predict
from kalcal.core.steps import GainSchedule, UpdateForm, check_form, gain_and_covariance, interval_transition, predict_covariance
from kalcal.core.timevarying import TimeVaryingModel, measured_components
from kalcal.errors import ConfigError, DataError
from kalcal.linalg import psd_factor
from kalcal.montecarlo.accumulators import SumBuffers
from kalcal.montecarlo.problem import FixedGainProblem, ProblemInfo
from kalcal.simulation.exact import UpdateRateTruth

__all__ = ["LogRecord", "LoggedFilter", "LoggedTruth", "LoggedGainProblem", "logged_arrays", "covariance_pass_over"]

#: why a filter over a log has no steady state (the report's steady-state section)
NOT_STEADY = "the filter's rows, noise or update spacing come from a log and change from update to update"


@dataclass(frozen=True)
class LogRecord:
    """The log a model file is verified over (settings section ``log``): its path as resolved when the run
    read it, its SHA-256 (so that a rebuild reads the same bytes or says it cannot) and a bag's topic."""

    path: str
    sha256: str
    topic: str = ""


def record_log(log: str | Path, topic: str | None = None) -> LogRecord:
    """The :class:`LogRecord` of a log file (its absolute path and digest)."""
    path = Path(log)
    if not path.is_file():
        raise DataError(f"--data: {path}: no such file")
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    return LogRecord(str(path.resolve()), digest, topic or "")


def check_record(record: LogRecord) -> None:
    """Refuse, in one line, a recorded log that is gone or whose bytes changed since the run read it."""
    path = Path(record.path)
    if not path.is_file():
        raise DataError(f"log.path: {record.path}: no such file (the run's log must be where it was to rebuild the run)")
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    if digest != record.sha256:
        raise DataError(f"log.sha256: {record.path} has changed since the run read it (sha256 {digest[:12]}..., recorded {record.sha256[:12]}...)")


@dataclass(frozen=True)
class LoggedFilter:
    """The filter's per-update model over a log. K updates, d states, p measured components.

    transitions Phi_k (K, d, d), process_cov Q_k (K, d, d), h H_k (K, p, d), v V_k (K, p, p); x0 (d,) and
    m0 (d, d), its prior at row 0; steps s_k (K,) the rows of each interval.
    """

    transitions: np.ndarray
    process_cov: np.ndarray
    h: np.ndarray
    v: np.ndarray
    x0: np.ndarray
    m0: np.ndarray
    steps: np.ndarray

    @property
    def state_dim(self) -> int:
        return self.transitions.shape[-1]

    @property
    def measurement_dim(self) -> int:
        return self.h.shape[-2]


@dataclass(frozen=True)
class LoggedTruth(UpdateRateTruth):
    """The exact update-rate truth with per-update noise factor L_k (K, n, r), rows H_k (K, p, n) and
    measurement factor G_k (K, p, p) (:class:`~kalcal.simulation.exact.UpdateRateTruth` holds one of each).
    No shared boundary sample and no deterministic model error (D_k = 0).

    ``estimate_offset`` (K, d): for a file with known inputs (a truth driven by them otherwise than the
    filter believes, :func:`driven_truth`, or as it believes), the filter's own response to the inputs f_k,
    which the kernel's input-free filter leaves out of its estimates and :class:`LoggedGainProblem` adds
    back (None: no inputs)."""

    estimate_offset: np.ndarray | None = None

    @property
    def normals_per_realization(self) -> int:
        return self.x0_factor.shape[1] + self.n_updates * (self.noise_factor.shape[-1] + self.h.shape[-2])


def covariance_pass_over(filt: LoggedFilter, form: UpdateForm = "joseph") -> GainSchedule:
    """The Riccati recursion over per-update matrices: M_k = Phi_k P_{k-1} Phi_k^T + Q_k, then the update
    with H_k and V_k, in any of the three forms, by the steps of :mod:`kalcal.core.steps` and
    :mod:`kalcal.core.sqrt_form` (those of :func:`~kalcal.core.steps.covariance_pass`, which a
    time-invariant model's constant arrays reproduce bit for bit). P_{-1} is m0, the prior at row 0."""
    check_form(form)
    n_updates, d, p = filt.transitions.shape[0], filt.state_dim, filt.measurement_dim
    prior = np.empty((n_updates, d, d))
    posterior = np.empty((n_updates, d, d))
    gains = np.empty((n_updates, d, p))
    innovation = np.empty((n_updates, p, p))
    if form == "sqrt":
        chol = cholesky_factor(filt.m0)
        factors: dict[bytes, np.ndarray] = {}
        for k in range(n_updates):
            key = filt.process_cov[k].tobytes()
            if key not in factors:
                factors[key] = cholesky_factor(filt.process_cov[k])
            _, chol = sqrt_predict(np.zeros(d), chol, filt.transitions[k], factors[key])
            prior[k] = gram(chol)
            gains[k], chol, s_chol = sqrt_gain_and_factor(chol, filt.h[k], cholesky_factor(filt.v[k]))
            posterior[k], innovation[k] = gram(chol), gram(s_chol)
    else:
        cov = filt.m0
        for k in range(n_updates):
            cov = predict_covariance(cov, filt.transitions[k], filt.process_cov[k])
            prior[k] = cov
            gains[k], cov, innovation[k] = gain_and_covariance(cov, filt.h[k], filt.v[k], form)
            posterior[k] = cov
    first_phi = filt.transitions[0] if n_updates else np.eye(d)
    first_q = filt.process_cov[0] if n_updates else np.zeros((d, d))
    return GainSchedule(prior, posterior, gains, innovation, first_phi, first_q, np.ascontiguousarray(filt.transitions))


class LoggedArrays(NamedTuple):
    """What a log gives the verification: the filter's and truth's per-update models, the update rows."""

    filter: LoggedFilter
    truth: LoggedTruth
    rows: np.ndarray  #: j_k, the log's 0-based row of each update, (K,)
    times: np.ndarray  #: the log's time of each update, s, (K,)
    components: np.ndarray  #: the measured components (indices into h's rows), (p',)


def _intervals(model: TimeVaryingModel, steps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Phi^s and Q_s of each interval of s steps (each distinct s computed once)."""
    cache: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    d = model.state_dim
    phis, qs = np.empty((steps.size, d, d)), np.empty((steps.size, d, d))
    for k, s in enumerate(steps.tolist()):
        if s not in cache:
            cache[s] = interval_transition(model.phi, model.gamma, model.w, s)
        phis[k], qs[k] = cache[s]
    return phis, qs


def logged_arrays(scenario, bound) -> LoggedArrays:
    """A model file bound to a log (:class:`~kalcal.scenarios.model_file.data.BoundModel`) as the
    verification's per-update arrays.

    Raises
    ------
    ConfigError
        One line naming the file (and the log's row where it is a row's fault): no measured row, a measured
        pattern that changes between update rows.
    """
    from kalcal.scenarios.model_file.model import _inputs_cancel

    f, t = bound.filter, bound.truth if bound.truth is not None else bound.filter
    measured = measured_components(f, bound.z) & np.all(np.isfinite(t.h), axis=2)
    updates = np.flatnonzero(np.any(measured, axis=1))
    if updates.size == 0:
        raise DataError(f"{bound.source}: no row measures any component ({', '.join(bound.table.measurements)}): nothing to verify")
    pattern = measured[updates[0]]
    changed = np.flatnonzero(np.any(measured[updates] != pattern, axis=1))
    if changed.size:
        j = int(updates[changed[0]])
        names = bound.measurement_names

        def listed(mask: np.ndarray) -> str:
            return ", ".join(n for n, m in zip(names, mask) if m)

        raise DataError(
            f"{bound.source}: row {j + 1} measures ({listed(measured[j])}) where row {updates[0] + 1} measures "
            f"({listed(pattern)}): the fixed-gain verification needs the same components at every update row"
        )
    components = np.flatnonzero(pattern)
    steps = np.diff(updates, prepend=0)
    phis, qs = _intervals(f, steps)
    h = f.h[updates][:, components]
    v = f.v[updates][:, components][:, :, components]
    filt = LoggedFilter(phis, qs, h, v, f.x0.copy(), f.m0.copy(), steps)
    if t is f:
        t_phis, t_qs, t_h, t_v = phis, qs, h, v
    else:
        t_phis, t_qs = _intervals(t, steps)
        t_h = t.h[updates][:, components]
        t_v = t.v[updates][:, components][:, :, components]
    factors = [psd_factor(q) for q in t_qs]
    rank = max(fac.shape[1] for fac in factors)
    noise = np.zeros((updates.size, t.state_dim, rank))  # the draws per update are constant: zero columns pad
    for k, fac in enumerate(factors):
        noise[k, :, : fac.shape[1]] = fac
    truth = LoggedTruth(
        transitions=np.ascontiguousarray(t_phis),
        noise_factor=noise,
        boundary_in=np.zeros(t.state_dim),
        boundary_out=np.zeros(t.state_dim),
        model_error=np.zeros((updates.size, t.state_dim)),
        x0_mean=t.x0.copy(),
        x0_factor=psd_factor(t.m0),
        h=np.ascontiguousarray(t_h),
        measurement_factor=np.linalg.cholesky(t_v),
        error_map=bound.truth_map,
    )
    if not _inputs_cancel(scenario):
        truth = driven_truth(truth, phis, h, _forcing(t, updates), _forcing(f, updates))
    elif f.b.size and f.u is not None and f.u.size:  # errors and innovations free of u; the estimates still carry the filter's response to it
        truth = dataclasses.replace(truth, estimate_offset=_response(phis, _forcing(f, updates)))
    return LoggedArrays(filt, truth, updates, np.asarray(bound.times)[updates], components)


def _response(phis: np.ndarray, forcing: np.ndarray) -> np.ndarray:
    """The filter's own response to the inputs at each update, f_k = Phi_k f_{k-1} + c^f_k (f_{-1} = 0), (K, d)."""
    response = np.empty_like(forcing)
    f = np.zeros(forcing.shape[1])
    for k in range(forcing.shape[0]):
        f = phis[k] @ f + forcing[k]
        response[k] = f
    return response


def _forcing(model: TimeVaryingModel, rows: np.ndarray) -> np.ndarray:
    """The inputs' share of each interval, c_k = sum_{j_{k-1} <= j < j_k} Phi^{j_k - 1 - j} B u_j, (K, d):
    x_{j_k} = Phi^{s_k} x_{j_{k-1}} + c_k + noise (u_j drives row j -> j + 1; j_{-1} = 0)."""
    drive = model.u @ model.b.T  # B u_j, (J, d)
    out = np.empty((rows.size, model.state_dim))
    c, start = np.zeros(model.state_dim), 0
    for k, end in enumerate(rows.tolist()):
        c = np.zeros(model.state_dim)
        for j in range(start, end):  # Horner's scheme over the interval's rows
            c = model.phi @ c + drive[j]
        out[k], start = c, end
    return out


def driven_truth(truth: LoggedTruth, phis: np.ndarray, h: np.ndarray, truth_forcing: np.ndarray, filter_forcing: np.ndarray) -> LoggedTruth:
    """``truth`` with known inputs that move it otherwise than the filter believes, as a truth of n + d + 1
    states [x; f; 1] whose last state is the constant 1 (no prior variance, no noise).

    The filter with inputs predicts xbar_k = Phi_k xhat_{k-1} + c^f_k. Writing xhat_k = f_k + xhat'_k, with
    f_k = Phi_k f_{k-1} + c^f_k (f_{-1} = 0) the filter's own response to the inputs, xhat'_k is the
    input-free filter (the same gains) run on z_k - H_k f_k, so that

        e_k = M x_k - xhat_k = [M, -I, 0] [x_k; f_k; 1] - xhat'_k,
        r_k = z_k - H_k xbar_k = [H_t,k, -H_k, 0] [x_k; f_k; 1] + v_k - H_k xbar'_k,

    exactly: the truth's x_k = A_k x_{k-1} + c^t_k + noise and f_k are both driven through the constant
    state's column, the map becomes [M, -I, 0] and the truth's rows [H_t,k, -H_k, 0]. The engine, the
    kernel and the exact analysis then run unchanged (a truth with its own states), and the error and the
    innovations get the deterministic offset M g_k - f_k and H_t,k g_k - H_k f_k (g the truth's response to
    u) in every realization: the mean error the checks test. The draws are the input-free truth's (the
    added states have zero rows in the prior's and the noise's factors), so a run with the inputs
    and one without use the same normals. The engine's filter estimates xhat'_k = xhat_k - f_k: f_k is
    kept as ``estimate_offset``, which :class:`LoggedGainProblem` adds to its estimates and the exact
    analysis to its moments of them (:func:`kalcal.analysis.fixed_gain.analyze_problem`), so that both
    report the filter's own xhat_k.

    Parameters
    ----------
    truth : LoggedTruth
        The input-free truth, n states (its map M (d, n), or none for the filter's d states).
    phis : ndarray, shape (K, d, d)
        The filter's Phi_k over each interval.
    h : ndarray, shape (K, p, d)
        The filter's H_k.
    truth_forcing, filter_forcing : ndarray, shapes (K, n) and (K, d)
        c^t_k and c^f_k, the inputs' share of each interval (:func:`_forcing`), in the states' units.
    """
    n_updates, n, r = truth.noise_factor.shape
    d = phis.shape[-1]
    size = n + d + 1
    transitions = np.zeros((n_updates, size, size))
    transitions[:, :n, :n] = truth.transitions
    transitions[:, n : n + d, n : n + d] = phis
    transitions[:, :n, -1] = truth_forcing
    transitions[:, n : n + d, -1] = filter_forcing
    transitions[:, -1, -1] = 1.0

    def padded(a: np.ndarray, axis: int) -> np.ndarray:
        width = [(0, 0)] * a.ndim
        width[axis] = (0, d + 1)
        return np.pad(a, width)

    error_map = np.eye(d, n) if truth.error_map is None else truth.error_map
    response = _response(phis, filter_forcing)
    x0_mean = padded(truth.x0_mean, 0)
    x0_mean[-1] = 1.0
    return LoggedTruth(
        transitions=transitions,
        noise_factor=padded(truth.noise_factor, 1),
        boundary_in=np.zeros(size),
        boundary_out=np.zeros(size),
        model_error=np.zeros((n_updates, size)),
        x0_mean=x0_mean,
        x0_factor=padded(truth.x0_factor, 0),
        h=np.ascontiguousarray(np.concatenate([truth.h, -h, np.zeros((*h.shape[:2], 1))], axis=2)),
        measurement_factor=truth.measurement_factor,
        error_map=np.hstack([error_map, -np.eye(d), np.zeros((d, 1))]),
        estimate_offset=response,
    )


class _Run(NamedTuple):
    posterior: np.ndarray
    residual: np.ndarray


@dataclass(frozen=True)
class LoggedGainProblem(FixedGainProblem):
    """:class:`~kalcal.montecarlo.problem.FixedGainProblem` over a log: per-update Phi_k, Q_k, H_k, V_k.

    ``filter_model`` is a :class:`LoggedFilter`, ``truth`` a :class:`LoggedTruth`; the exact engine alone.
    Its moment sums, realizations shown and statistics are the parent's, through the compiled kernel
    :func:`~kalcal.scenarios.model_file.logged_kernels.logged_block_moments` and the numpy reference
    (:meth:`sample`, :meth:`filter`) that tests hold it to.
    """

    NOT_STEADY = NOT_STEADY

    def steady_state_reason(self) -> str:
        """Its rows, noise or update spacing change from update to update (:data:`NOT_STEADY`)."""
        return NOT_STEADY

    def __post_init__(self) -> None:
        d, p = self.filter_model.state_dim, self.filter_model.measurement_dim
        if (self.truth.error_dim, self.truth.h.shape[-2]) != (d, p):
            raise ValueError(f"truth: expected {d} filter states and {p} measurements")
        self._adopt(covariance_pass_over(self.filter_model, self.form))

    @property
    def engines(self) -> tuple[str, ...]:
        return ("exact",)

    def sample(self, rng: np.random.Generator, n: int, engine: str = "exact") -> tuple[np.ndarray, np.ndarray]:
        """States (n, K, n_t) and measurements (n, K, p), drawn as the kernel draws them: (d0, n) for the
        prior, then (r + p, n) per update."""
        from kalcal.montecarlo.problem import check_engine

        check_engine(self, engine)
        truth = self.truth
        d0 = truth.x0_factor.shape[1]
        n_updates, n_t, r = truth.noise_factor.shape
        p = truth.h.shape[-2]
        y = (truth.x0_mean[:, None] + truth.x0_factor @ rng.standard_normal((d0, n))).T
        states, measurements = np.empty((n, n_updates, n_t)), np.empty((n, n_updates, p))
        for k in range(n_updates):
            step = rng.standard_normal((r + p, n)).T
            y = y @ truth.transitions[k].T + step[:, :r] @ truth.noise_factor[k].T
            states[:, k] = y
            measurements[:, k] = y @ truth.h[k].T + step[:, r:] @ truth.measurement_factor[k].T
        return states, measurements

    def filter(self, measurements: np.ndarray) -> _Run:
        """The fixed-gain filter over measurements (n, K, p), per-update H_k: posterior and residual."""
        sched, filt = self.schedule, self.filter_model
        n, n_updates, _ = measurements.shape
        x = np.broadcast_to(filt.x0, (n, filt.state_dim))
        posterior = np.empty((n, n_updates, filt.state_dim))
        residual = np.empty_like(measurements)
        for k in range(n_updates):
            xbar = x @ sched.transitions[k].T
            residual[:, k] = measurements[:, k] - xbar @ filt.h[k].T
            x = xbar + residual[:, k] @ sched.gain[k].T
            posterior[:, k] = x
        return _Run(posterior, residual)

    def run_block(self, rng: np.random.Generator, n: int, engine: str = "exact"):
        """The parent's block, its estimates those of the filter with its inputs (``truth.estimate_offset``)."""
        block = super().run_block(rng, n, engine)
        offset = self.truth.estimate_offset
        return block if offset is None else block._replace(estimate=block.estimate + offset)

    def shown_realization(self, rng: np.random.Generator, n: int, index: int, engine: str = "exact"):
        """The parent's realization, its estimate that of the filter with its inputs."""
        error, estimate, cov = super().shown_realization(rng, n, index, engine)
        offset = self.truth.estimate_offset
        return error, estimate if offset is None else estimate + offset, cov

    def block_sums(self, rng: np.random.Generator, n: int, engine: str = "exact"):
        """The parent's sums, with the estimates' shifted by the filter's own response to the inputs f_k
        where the truth carries one: sum (xhat' + f) = S + n f, sum (xhat' + f)(xhat' + f)^T = S2 + S f^T +
        f S^T + n f f^T, sum e (xhat' + f)^T = S_ex + (sum e) f^T (the errors, innovations, NEES, NIS and
        histograms do not involve the estimate)."""
        sums = super().block_sums(rng, n, engine)
        f = self.truth.estimate_offset
        if f is None:
            return sums
        total = sums.estimate
        outer = total[:, :, None] * f[:, None, :]
        white = sums.whitened_estimate  # None or empty: every realization shares P_k
        if white is not None and white.size:
            white = white + sums.whitened_error[:, :, None] * f[:, None, :]
        return dataclasses.replace(
            sums,
            estimate=total + n * f,
            estimate_outer=sums.estimate_outer + outer + np.swapaxes(outer, 1, 2) + n * f[:, :, None] * f[:, None, :],
            error_estimate=sums.error_estimate + sums.error[:, :, None] * f[:, None, :],
            whitened_estimate=white,
        )

    def _gains(self) -> tuple:
        """The kernel's filter arguments, as the parent's, with H_k per update (K, p, d)."""
        return (
            np.ascontiguousarray(self.schedule.transitions),
            np.ascontiguousarray(self.filter_model.h),
            self.schedule.gain,
            self.filter_model.x0,
            np.ascontiguousarray(self._state_whitener),
            np.ascontiguousarray(self._innovation_whitener),
            *self._centers,
        )

    def _exact_block(self, rng: np.random.Generator, n: int, sums: SumBuffers, traced: int = -1) -> np.ndarray:
        from kalcal.scenarios.model_file import logged_kernels

        if not -1 <= traced < n:
            raise ValueError(f"traced realization must lie in [-1, {n}), got {traced}")
        truth = self.truth
        d0 = truth.x0_factor.shape[1]
        first = rng.standard_normal((d0, n))
        trace = np.zeros((2, truth.n_updates, self.filter_model.state_dim) if traced >= 0 else (0, 0, 0))
        logged_kernels.logged_block_moments(
            truth.x0_mean[:, None] + truth.x0_factor @ first,
            rng,
            truth.transitions,
            np.ascontiguousarray(truth.noise_factor),
            truth.h,
            np.ascontiguousarray(truth.measurement_factor),
            *self._gains(),
            sums,
            np.empty((0, 0)) if truth.error_map is None else np.ascontiguousarray(truth.error_map),
            traced,
            trace,
        )
        return trace

    def _mean_run(self) -> tuple[np.ndarray, _Run]:
        """The truth's mean trajectory M E[x_k] (K, d) and the filter's run over its mean measurements, with
        H_k per update and no model error (the parent's :meth:`expected_mean_error` and shape centers use it)."""
        truth = self.truth
        mean = np.empty((truth.n_updates, truth.state_dim))
        y = truth.x0_mean
        for k in range(truth.n_updates):
            y = truth.transitions[k] @ y
            mean[k] = y
        run = self.filter(np.einsum("kij,kj->ki", truth.h, mean)[None])
        if truth.error_map is not None:
            mean = mean @ truth.error_map.T
        return mean, run



def logged_problem(scenario, form: UpdateForm = "joseph", residual_pairs: bool = True) -> LoggedGainProblem:
    """A model file's filter against its truth over the scenario's log (``scenario.arrays``)."""
    from kalcal.scenarios.model_file.model import inputs_note

    arrays = scenario.arrays
    m = scenario.model
    info = ProblemInfo(
        scenario=m.name,
        update_times=arrays.times,
        state_names=m.state_names,
        state_units=m.state_units,
        measurement_names=tuple(m.measurement_names[i] for i in arrays.components),
        measurement_units=tuple(m.measurement_units[i] for i in arrays.components),
        capabilities=scenario.capabilities,
        notes=inputs_note(scenario, over_log=True),
    )
    try:
        if scenario.filter.diffuse:  # the exact diffuse gains, checked after the diffuse period
            from kalcal.scenarios.model_file.diffuse import diffuse_logged_problem

            return diffuse_logged_problem(scenario, info, arrays, form, residual_pairs)
        return LoggedGainProblem(info=info, filter_model=arrays.filter, truth=arrays.truth, form=form, residual_pairs=residual_pairs)
    except np.linalg.LinAlgError:
        raise ConfigError(
            f"{m.file}: the filter's covariance P_k is singular at some update of the log (give the unobserved "
            "states prior variance in m0 or process noise through gamma and w)"
        ) from None


def logged_sources(scenario) -> list[Source]:
    """The error budget's sources over a log, per update (shares of shape (K, ., .)): the truth's prior by
    the blocks of m0, its process noise by the blocks of w (each block's Q_k over the interval's s_k
    steps, so the shares sum to Q_k), each measured component's block of V_k (the blocks of v: a std
    column scales a component, never links two)."""
    from kalcal.core.sources import blocks, covariance_sources

    arrays = scenario.arrays
    truth, model = arrays.truth, scenario.truth
    n = model.state_dim  # the truth's own states: a truth driven by inputs carries d + 1 more, without noise
    names = getattr(model, "state_names", None) or scenario.model.state_names
    if n != len(names):
        names = tuple(f"x{i + 1}" for i in range(n))
    process = []
    for index in blocks(model.w):
        cache: dict[int, np.ndarray] = {}
        gamma, w = model.gamma[:, index], model.w[np.ix_(index, index)]
        share = np.zeros((truth.n_updates, truth.state_dim, truth.state_dim))
        for k, s in enumerate(arrays.filter.steps.tolist()):
            if s not in cache:
                cache[s] = interval_transition(model.phi, gamma, w, s)[1]
            share[k, :n, :n] = cache[s]
        process.append(("+".join(f"w{i + 1}" for i in index), share, 0.0))
    r = truth.measurement_factor @ np.swapaxes(truth.measurement_factor, -1, -2)
    sources = covariance_sources(
        model.m0, r[0], process, names, tuple(scenario.model.measurement_names[i] for i in arrays.components)
    )
    out = []
    for source in sources:
        zero_q = np.zeros((truth.n_updates, truth.state_dim, truth.state_dim))
        prior = np.zeros((truth.state_dim, truth.state_dim))
        prior[:n, :n] = source.prior_cov[:n, :n]
        source = dataclasses.replace(source, prior_cov=prior)
        if source.kind == "measurement":
            block = source.measurement_cov != 0  # the block of R_0, which every R_k shares
            out.append(dataclasses.replace(source, process_cov=zero_q, measurement_cov=np.where(block, r, 0.0)))
        else:
            zero_r = np.zeros_like(r)
            out.append(dataclasses.replace(source, process_cov=source.process_cov if source.kind == "process" else zero_q, measurement_cov=zero_r))
    return out
