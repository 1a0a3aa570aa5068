"""The error model over each interval between fixes: its pieces, their composition, the scale-factor change.

Between two fixes the filter propagates with the model of the Monte Carlo, piece by piece: the steps
between samples, cut at the fixes. Each piece's transition is
:func:`~kalcal.scenarios.accel_gps.discretization.error_transition` (the bias as the scheme integrates its samples, with
the decay and noise of :func:`~kalcal.scenarios.accel_gps.discretization.bias_discretization`: a Gauss-Markov bias decays
by exp(-dt_j / tau) at each sample, with the exact discrete noise, over each step's own dt_j), and a piece
of length h adds the accelerometer noise g = [h^2/2, h, 0] sigma_a. The products over each interval's
pieces are composed by compiled passes over chunks of pieces (:func:`composed_sources`), and only the
3x3 update runs in a loop over fixes. This is exactly the filter that ``verify`` runs (the same
per-sample Phi, Gamma and W, the same prior and updates) on a log that is evenly spaced at the
scenario's rates, with a fix on every ``steps_per_update``-th sample from the first and none skipped
or given its own accuracy, without a scale state (``scale_std`` = 0: here the scale column uses the
measured acceleration, in ``verify`` the true profile) and with ``init="prior"`` (``"first-fix"`` starts
later, from the first fix and the GPS noise). A step cut by a fix is treated as two pieces with
independent noise (the same sample's noise, and with the trapezoid rule the same bias noise, really
enters both; the difference is one sample's share of a whole interval).
"""

from __future__ import annotations

import numba
import numpy as np

from kalcal.linalg import symmetrize
from kalcal.scenarios.accel_gps.discretization import bias_discretization, error_transition

__all__ = ["CHUNK_PIECES", "SOURCES", "composed_sources", "continuous_bias_model", "interval_sources",
           "scale_parameters"]  # fmt: skip


#: the process noise's sources, each composed with unit variance: Q_k = sum_r variance_r Q_k^(r)
SOURCES = ("accel_noise", "bias_walk", "bias_markov")


def interval_sources(imu_time, steps, cuts, settings, period, scheme) -> tuple[np.ndarray, np.ndarray]:
    """Every piece between two cuts (samples and fixes): its transition and its noise inputs per source.

    A piece [c_i, c_{i+1}] lies in the sample step [t_j, t_{j+1}]; its transition is
    :func:`~kalcal.scenarios.accel_gps.discretization.error_transition` over its part of that step, with the
    step's bias decay (:func:`~kalcal.scenarios.accel_gps.discretization.bias_discretization`). Its noise
    inputs, one column per source of :data:`SOURCES`, each for a unit variance: the accelerometer sample
    held over it, g = [h^2/2, h, 0] (times sigma_a); the bias noise's weights times sqrt(step_j / period)
    (times bias_walk_std); and, for a Gauss-Markov bias, times sqrt(1 - exp(-2 step_j / tau)) (times
    bias_std). The step's bias noise variance q_j of ``bias_discretization`` is the sum of the last two
    sources' variances, so the noise covariance is linear in (sigma_a^2, bias_walk_std^2, bias_std^2).

    Returns
    -------
    phis : ndarray, shape (N, 3, 3)
    inputs : ndarray, shape (N, 3, 3)
        [piece, state, source].
    """
    starts, ends = cuts[:-1], cuts[1:]
    j = np.clip(np.searchsorted(imu_time, starts, side="right") - 1, 0, imu_time.size - 2)
    step = steps[j]
    closes = ends == imu_time[j + 1]
    decay, _ = bias_discretization(settings, step, period)
    into_end = np.where(closes, step, ends - imu_time[j])
    phis, bias_input = error_transition(starts - imu_time[j], into_end, step, decay, scheme, closes)
    h = ends - starts
    tau = settings.bias_correlation_time
    markov = np.sqrt(-np.expm1(-2.0 * step / tau)) if tau > 0 else np.zeros_like(step)
    inputs = np.stack(
        [np.stack([0.5 * h * h, h, np.zeros_like(h)], axis=1), bias_input * np.sqrt(step / period)[:, None], bias_input * markov[:, None]],
        axis=-1,
    )
    return phis, inputs


#: pieces composed at a time by :func:`composed_sources`: a chunk's arrays (at most about 300 bytes a piece
#: at once, 5 MB) are freed after each chunk and their memory reused by the allocator for the next, so
#: that the composition's working memory does not grow with the number of pieces and is not mapped afresh
#: (docs/accel-gps.md, "Speed")
CHUNK_PIECES = 1 << 14


def composed_sources(
    imu_time, steps, cuts, owner, n_intervals: int, settings, period: float, scheme: str, *, chunk: int = CHUNK_PIECES
) -> tuple[np.ndarray, np.ndarray]:
    """Every interval's transition and process noise by source: the pieces between ``cuts`` (made by
    :func:`interval_sources`) composed into their intervals, ``chunk`` pieces at a time.

    The same values, bit for bit, as composing every piece in one pass (tests/calibration/test_interval_model.py):
    each piece's transition and inputs are its own, and an interval's products are taken in its pieces'
    order across chunks as within one.

    Parameters
    ----------
    imu_time : ndarray, shape (M,)
        Accelerometer sample times, s, increasing.
    steps : ndarray, shape (M - 1,)
        ``np.diff(imu_time)``, s.
    cuts : ndarray, shape (N + 1,)
        The pieces' ends, s, increasing, within the log: N pieces.
    owner : ndarray of int, shape (N,)
        Each piece's interval, nondecreasing, in [0, n_intervals).
    n_intervals : int
        K, the intervals (fixes).
    settings : AccelGpsTruth
        The filter's settings (the bias model).
    period : float
        The nominal sample period, s.
    scheme : {"euler", "trapezoid"}
    chunk : int
        Pieces per compiled pass (>= 1).

    Returns
    -------
    phis : ndarray, shape (K, 3, 3)
        Phi_k; I for an interval without pieces.
    sources : ndarray, shape (R, K, 3, 3)
        Q_k^(r) for each source of :data:`SOURCES` at unit variance, exactly symmetric; 0 without pieces.
    """
    if isinstance(chunk, bool) or not isinstance(chunk, (int, np.integer)) or chunk < 1:
        raise ValueError(f"chunk: expected a whole number of pieces >= 1, got {chunk!r}")
    chunk = int(chunk)
    if not np.issubdtype(np.asarray(owner).dtype, np.integer):
        raise ValueError(f"owner: expected whole interval numbers, got dtype {np.asarray(owner).dtype}")
    owner = np.ascontiguousarray(owner, dtype=np.int64)
    if owner.shape != (cuts.size - 1,):
        raise ValueError(f"owner: expected one interval per piece ({cuts.size - 1}), got shape {owner.shape}")
    if owner.size and (owner.min() < 0 or owner.max() >= n_intervals):  # the kernel does not check its indices
        raise ValueError(f"owner: intervals must lie in [0, {n_intervals}), got [{owner.min()}, {owner.max()}]")
    out_phi = np.broadcast_to(np.eye(3), (n_intervals, 3, 3)).copy()
    out_q = np.zeros((len(SOURCES), n_intervals, 3, 3))
    for start in range(0, cuts.size - 1, chunk):
        stop = min(start + chunk, cuts.size - 1)
        phis, inputs = interval_sources(imu_time, steps, cuts[start : stop + 1], settings, period, scheme)
        assert inputs.shape[2] == out_q.shape[0], "interval_sources makes one input column per source"
        _accumulate_by_source(phis, inputs, owner[start:stop], out_phi, out_q)
        del phis, inputs  # freed before the next chunk's are made
    return out_phi, symmetrize(out_q)  # exactly symmetric: the recursion leaves it so only to rounding


#: Gauss-Legendre nodes and weights on [0, 1] for :func:`continuous_bias_model`'s integrals
_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(16)
_NODES, _WEIGHTS = 0.5 * (_NODES + 1.0), 0.5 * _WEIGHTS


def _bias_column(u: np.ndarray, rate: float) -> np.ndarray:
    """Phi(u)[:, 2] of the continuous error model dp' = dv, dv' = -b, b' = -rate b: [-g2, -g1, exp(-rate u)],
    g1 = (1 - exp(-rate u)) / rate, g2 = (u - g1) / rate (u, u^2 / 2 at rate 0), shape u.shape + (3,)."""
    x = rate * u
    small = x < 1e-2
    with np.errstate(divide="ignore", invalid="ignore"):
        g1 = np.where(small, u * (1 - x / 2 + x * x / 6 - x**3 / 24), -np.expm1(-x) / rate)
        g2 = np.where(small, u * u * (0.5 - x / 6 + x * x / 24 - x**3 / 120), (x + np.expm1(-x)) / rate**2)
    return np.stack([-g2, -g1, np.exp(-x)], axis=-1)


def continuous_bias_model(spans: np.ndarray, tau: float) -> tuple[np.ndarray, np.ndarray]:
    """The bias's part of the continuous-time error model over intervals of ``spans`` seconds.

    With b' = -b / tau + white noise (tau = 0: a constant or random-walk bias, rate 0), the transition's
    bias column over T is c(T) = [-g2(T), -g1(T), exp(-T / tau)] and the noise of a unit-PSD bias
    input is J(T) = int_0^T c(u) c(u)^T du (16-point Gauss-Legendre: the integrand is smooth, the rule
    exact to rounding for T / tau up to a few). The random walk's unit PSD is 1 / period per unit
    bias_walk_std^2, the Gauss-Markov bias's 2 / tau per unit bias_std^2.

    Returns
    -------
    column : ndarray, shape (K, 3)
    integral : ndarray, shape (K, 3, 3)
        J(T_k), s (times the PSD: (m/s^2)^2 / s).
    """
    spans = np.asarray(spans, dtype=float)
    rate = 1.0 / tau if tau > 0 else 0.0
    column = _bias_column(spans, rate)
    u = spans[:, None] * _NODES[None, :]
    c = _bias_column(u, rate)
    integral = np.einsum("kn,kna,knb->kab", spans[:, None] * _WEIGHTS[None, :], c, c)
    return column, integral


@numba.njit(cache=True, nogil=True)
def _accumulate_by_source(phis, inputs, owner, out_phi, out_q):
    """Compose pieces into running products, in place: piece i of interval k = ``owner[i]`` takes
    ``out_phi[k]`` to T_i out_phi[k] and, for each source r, ``out_q[r, k]`` to T_i out_q[r, k] T_i^T + g g^T,
    g = ``inputs[i, :, r]``. Pieces given in consecutive chunks compose as they would in one call;
    ``out_q`` is made exactly symmetric (:func:`kalcal.linalg.symmetrize`) once all are in.

    Unchecked (its caller, :func:`composed_sources`, checks): phis (N, 3, 3), inputs (N, 3, R), owner (N,)
    in [0, K), out_phi (K, 3, 3), out_q (R, K, 3, 3)."""
    tmp = np.empty((3, 3))
    for i in range(phis.shape[0]):
        k = owner[i]
        t = phis[i]
        _transition_step(t, out_phi[k], tmp)
        for r in range(inputs.shape[2]):
            _covariance_step(t, out_q[r, k], inputs[i, :, r : r + 1], tmp)


@numba.njit(cache=True, nogil=True, inline="always")
def _transition_step(t, phi, tmp):
    """phi <- t phi (3 x 3, in place; ``tmp`` scratch)."""
    for a in range(3):
        for b in range(3):
            tmp[a, b] = t[a, 0] * phi[0, b] + t[a, 1] * phi[1, b] + t[a, 2] * phi[2, b]
    phi[:, :] = tmp


@numba.njit(cache=True, nogil=True, inline="always")
def _covariance_step(t, q, g, tmp):
    """q <- t q t^T + g g^T (3 x 3 and 3 x m, in place; ``tmp`` scratch)."""
    for a in range(3):
        for b in range(3):
            tmp[a, b] = t[a, 0] * q[0, b] + t[a, 1] * q[1, b] + t[a, 2] * q[2, b]
    for a in range(3):
        for b in range(3):
            value = tmp[a, 0] * t[b, 0] + tmp[a, 1] * t[b, 1] + tmp[a, 2] * t[b, 2]
            for r in range(g.shape[1]):
                value += g[a, r] * g[b, r]
            q[a, b] = value


def scale_parameters(states: np.ndarray, covariances: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """From the filter's [dp, dv, b', s'] to [dp, dv, b, s], b = b' / (1 - s'), s = s' / (1 - s').

    With a scale-factor error the measured acceleration is a_c = (1 + s) a + b + w, so the true one is
    a = (1 - s') a_c - b' - w / (1 + s) with s' = s / (1 + s), b' = b / (1 + s): the error dynamics are
    exactly linear in (b', s') with the measured a_c in the transition, which is what a filter of a log
    has. The covariance follows by the delta method, J P J^T.
    """
    b_prime, s_prime = states[:, 2], states[:, 3]
    one_minus = 1.0 - s_prime
    converted = states.copy()
    converted[:, 2], converted[:, 3] = b_prime / one_minus, s_prime / one_minus
    jacobian = np.broadcast_to(np.eye(4), covariances.shape).copy()
    jacobian[:, 2, 2] = 1.0 / one_minus
    jacobian[:, 2, 3] = b_prime / one_minus**2
    jacobian[:, 3, 3] = 1.0 / one_minus**2
    return converted, symmetrize(jacobian @ covariances @ np.swapaxes(jacobian, 1, 2))
