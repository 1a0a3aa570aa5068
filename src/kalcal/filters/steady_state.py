"""The steady state of a time-invariant filter: the discrete algebraic Riccati equation (DARE).

Over one update interval the model is x_k = Phi x_{k-1} + w_k, w_k ~ N(0, Q), z_k = H x_k + v_k,
v_k ~ N(0, V) (Phi = Phi_m and Q = Q_m of :func:`~kalcal.core.steps.interval_transition`). The prior
covariance M_k of the time-varying filter follows the Riccati recursion; its fixed point M_inf solves

    M = Phi M Phi^T - Phi M H^T (H M H^T + V)^{-1} H M Phi^T + Q

scipy's ``solve_discrete_are(a, b, q, r)`` solves a^T X a - X - a^T X b (r + b^T X b)^{-1} b^T X a + q = 0
for the control problem; the filtering equation is its dual, a = Phi^T and b = H^T. Then
S_inf = H M_inf H^T + V, K_inf = M_inf H^T S_inf^{-1} and P_inf = (I - K_inf H) M_inf (I - K_inf H)^T +
K_inf V K_inf^T.

M_k converges to M_inf from any positive semi-definite M0 when M_inf is *stabilizing*: the closed loop
Phi (I - K_inf H) has every eigenvalue inside the unit circle. That holds when (Phi, H) is detectable and
(Phi, Q^{1/2}) stabilizable. A mode on or outside the unit circle that no process noise reaches (a constant
bias: eigenvalue 1, Q zero on it) breaks the second condition: the variance of such a mode goes to zero
like 1/k and never settles, and the DARE has no stabilizing solution (scipy may still return the
non-stabilizing limit, or fail). :func:`steady_state` says which, and why; :func:`model_steady_state_view`
sets it beside the time-varying filter's P_k (:func:`convergence`), and :func:`no_steady_state` records why
a filter that is not time-invariant has none.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kalcal.core.model import LinearGaussianModel
from kalcal.core.steps import gain_and_covariance, interval_transition
from kalcal.linalg import psd_factor

#: the default tolerance of :func:`convergence`: ||P_k - P_inf|| / ||P_inf|| below this counts as converged
CONVERGENCE_TOLERANCE = 1e-3


@dataclass(frozen=True)
class SteadyState:
    """The DARE's solution for a time-invariant filter, or why there is no stabilizing one.

    The matrices are None when scipy found no solution at all; when ``stabilizing`` is False they are
    the (non-stabilizing) solution scipy returned, which M_k need not approach.
    """

    prior_cov: np.ndarray | None  #: M_inf, (d, d)
    posterior_cov: np.ndarray | None  #: P_inf, (d, d)
    gain: np.ndarray | None  #: K_inf, (d, p)
    innovation_cov: np.ndarray | None  #: S_inf, (p, p)
    stabilizing: bool  #: every eigenvalue of Phi (I - K_inf H) inside the unit circle
    spectral_radius: float | None  #: of Phi (I - K_inf H)
    reason: str  #: why there is no stabilizing solution ("" when there is)

    @property
    def exists(self) -> bool:
        """A stabilizing steady state, which the time-varying filter converges to."""
        return self.stabilizing and self.prior_cov is not None


@dataclass(frozen=True)
class Convergence:
    """How fast P_k approaches P_inf."""

    relative_gap: np.ndarray  #: ||P_k - P_inf||_F / ||P_inf||_F, (K,)
    state_gap: np.ndarray  #: |P_k,ii - P_inf,ii| / P_inf,ii per state, (K, d) (inf where P_inf,ii = 0)
    tolerance: float
    update: int | None  #: first update k after which relative_gap stays below tolerance; None: not within the run
    state_update: tuple[int | None, ...]  #: the same per state, from state_gap


def _uncontrolled_modes(phi: np.ndarray, factor: np.ndarray, *, rtol: float = 1e-9) -> list[tuple[complex, np.ndarray]]:
    """Modes of Phi on or outside the unit circle that the columns of ``factor`` never reach.

    The reachable subspace is the range of C = [B, Phi B, ..., Phi^{d-1} B] (B = ``factor``, (d, r)); with
    an orthonormal basis N of its complement, the unreached dynamics are N^T Phi N (Phi is block
    triangular in the basis [range C, N]). The states are first scaled by the row norms of C, an
    equivalence transform that keeps the rank decision (singular values above ``rtol`` times the largest)
    from depending on units. Returns (lambda, |direction| in the original states) per mode.
    """
    d = phi.shape[0]
    blocks, block = [], np.asarray(factor, dtype=float).reshape(d, -1)
    for _ in range(d):
        blocks.append(block)
        block = phi @ block
    reach = np.concatenate(blocks, axis=1)
    scale = np.linalg.norm(reach, axis=1)
    scale = np.where(scale > 0, scale, 1.0)
    reach, phi_scaled = reach / scale[:, None], phi * scale[None, :] / scale[:, None]
    u, sigma, _ = np.linalg.svd(reach) if reach.size else (np.eye(d), np.zeros(0), None)
    rank = int(np.sum(sigma > rtol * sigma.max(initial=0.0))) if sigma.size and sigma.max() > 0 else 0
    complement = u[:, rank:]
    if complement.shape[1] == 0:
        return []
    values, vectors = np.linalg.eig(complement.T @ phi_scaled @ complement)
    modes = []
    for value, vector in zip(values, vectors.T):
        if abs(value) >= 1.0 - 1e-9:
            modes.append((complex(value), np.abs(scale * (complement @ vector))))
    return modes


def _describe(modes, state_names) -> str:
    parts = []
    for value, vector in modes:
        main = int(np.argmax(vector))
        name = state_names[main] if state_names else f"state {main}"
        shown = f"{value.real:.6g}" if abs(value.imag) < 1e-12 else f"{value:.6g}"
        parts.append(f"eigenvalue {shown} (mostly {name})")
    return ", ".join(parts)


def steady_state(model: LinearGaussianModel, state_names: tuple[str, ...] = ()) -> SteadyState:
    """M_inf, P_inf, K_inf and S_inf of a time-invariant model at its update rate, or why not.

    Parameters
    ----------
    model : LinearGaussianModel
        Measured every ``steps_per_update`` samples; Phi and Q are taken over one update interval.
    state_names : tuple of str, optional
        Names of the states, quoted in the reason.

    Returns
    -------
    SteadyState
        ``exists`` is True when the DARE has a stabilizing solution; otherwise ``reason`` says what
        failed: the PBH test (a mode on or outside the unit circle unreached by the noise, or unseen by
        H), scipy's error, or a closed loop that is not stable.
    """
    phi, q = interval_transition(model.phi, model.gamma, model.w, model.steps_per_update)
    h, v = model.h, model.v
    causes = []
    unreached = _uncontrolled_modes(phi, psd_factor(q))
    if unreached:
        causes.append(
            f"(Phi, Q^1/2) is not stabilizable: no process noise reaches the mode at {_describe(unreached, state_names)}, "
            "so its variance keeps shrinking and never settles"
        )
    unseen = _uncontrolled_modes(phi.T, h.T)
    if unseen:
        causes.append(f"(Phi, H) is not detectable: the measurements never see the mode at {_describe(unseen, state_names)}")
    import scipy.linalg

    try:
        with np.errstate(all="ignore"):
            prior = scipy.linalg.solve_discrete_are(phi.T, h.T, q, v)
    except (np.linalg.LinAlgError, ValueError) as exc:
        reason = "; ".join(causes + [f"scipy.linalg.solve_discrete_are failed: {exc}"])
        return SteadyState(None, None, None, None, False, None, reason)
    if not np.all(np.isfinite(prior)):
        reason = "; ".join(causes + ["scipy.linalg.solve_discrete_are returned a non-finite solution"])
        return SteadyState(None, None, None, None, False, None, reason)
    prior = 0.5 * (prior + prior.T)
    gain, posterior, innovation = gain_and_covariance(prior, h, v, "joseph")
    closed_loop = phi @ (np.eye(phi.shape[0]) - gain @ h)
    radius = float(np.max(np.abs(np.linalg.eigvals(closed_loop))))
    stabilizing = radius < 1.0 - 1e-9 and not causes
    if not stabilizing and not causes:
        causes.append(f"the solution is not stabilizing: Phi (I - K H) has spectral radius {radius:.6g}")
    reason = "" if stabilizing else "; ".join(causes)
    return SteadyState(prior, posterior, gain, innovation, stabilizing, radius, reason)


def _first_settled(below: np.ndarray) -> int | None:
    """First index after which ``below`` (K,) is True to the end; None if its last entry is False."""
    if below.size == 0 or not below[-1]:
        return None
    above = np.flatnonzero(~below)
    return int(above[-1]) + 1 if above.size else 0


def convergence(posterior_cov: np.ndarray, steady: np.ndarray, tolerance: float = CONVERGENCE_TOLERANCE) -> Convergence:
    """How fast the time-varying P_k approaches P_inf.

    Parameters
    ----------
    posterior_cov : ndarray, shape (K, d, d)
        P_k of the time-varying filter (a :class:`~kalcal.core.steps.GainSchedule`'s posterior_cov).
    steady : ndarray, shape (d, d)
        P_inf.
    tolerance : float
        ||P_k - P_inf||_F / ||P_inf||_F below this counts as converged (the norm weighs states by their
        units; ``state_gap`` gives each variance relative to its own steady value).

    Returns
    -------
    Convergence
        ``update``: the first update k (0-based) after which the relative gap stays below ``tolerance``,
        None when it is still above at the last update (not within the run).
    """
    posterior_cov = np.asarray(posterior_cov, dtype=float)
    difference = posterior_cov - steady
    gap = np.linalg.norm(difference, axis=(-2, -1)) / np.linalg.norm(steady)
    diagonal = np.diagonal(steady)
    with np.errstate(divide="ignore", invalid="ignore"):
        state_gap = np.abs(np.diagonal(difference, axis1=-2, axis2=-1)) / diagonal
    state_gap = np.where(np.isnan(state_gap), np.inf, state_gap)
    return Convergence(
        relative_gap=gap,
        state_gap=state_gap,
        tolerance=tolerance,
        update=_first_settled(gap < tolerance),
        state_update=tuple(_first_settled(state_gap[:, i] < tolerance) for i in range(steady.shape[0])),
    )


@dataclass(frozen=True)
class SteadyStateView:
    """The steady state of a run's filter beside its time-varying P_k, or why it has none. d states, K updates."""

    applies: bool  #: the filter is time-invariant
    reason: str  #: why it does not apply, or why there is no stabilizing solution ("" otherwise)
    state_names: tuple[str, ...]
    state_units: tuple[str, ...]
    times: np.ndarray | None = None  #: update times, s, (K,)
    posterior_cov: np.ndarray | None = None  #: P_k of the time-varying filter, (K, d, d)
    result: SteadyState | None = None
    convergence: Convergence | None = None  #: only for a stabilizing solution

    @property
    def has_matrices(self) -> bool:
        """scipy returned a solution (stabilizing or not) that can be shown."""
        return self.result is not None and self.result.posterior_cov is not None

    def converged_time(self) -> float | None:
        """Time (s) of the update after which P_k stays within the tolerance of P_inf, if any."""
        if self.convergence is None or self.convergence.update is None or self.times is None:
            return None
        return float(self.times[self.convergence.update])


def model_steady_state_view(
    model: LinearGaussianModel,
    posterior_cov: np.ndarray,
    times: np.ndarray,
    state_names: tuple[str, ...],
    state_units: tuple[str, ...],
) -> SteadyStateView:
    """The steady state of a time-invariant filter, with its time-varying P_k and how fast they meet.

    Parameters
    ----------
    model : LinearGaussianModel
        The filter's model (time-invariant: no per-interval transitions).
    posterior_cov : ndarray, shape (K, d, d)
        P_k of the time-varying filter (its :class:`~kalcal.core.steps.GainSchedule`'s posterior_cov).
    times : ndarray, shape (K,)
        Update times, s.
    state_names, state_units : tuple of str, length d

    Returns
    -------
    SteadyStateView
        ``applies`` True; ``convergence`` only where the DARE has a stabilizing solution.
    """
    names, units = tuple(state_names), tuple(state_units)
    result = steady_state(model, names)
    progress = convergence(posterior_cov, result.posterior_cov) if result.exists else None
    return SteadyStateView(True, result.reason, names, units, np.asarray(times), posterior_cov, result, progress)


def no_steady_state(reason: str, state_names: tuple[str, ...], state_units: tuple[str, ...]) -> SteadyStateView:
    """The view of a filter that is not time-invariant: ``applies`` False and ``reason`` why."""
    return SteadyStateView(False, reason, tuple(state_names), tuple(state_units))
