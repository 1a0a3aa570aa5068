"""The accelerometer/GPS error state over one sample step: the bias's discretization and the transition.

The one place where the scenario's continuous bias model (constant, random walk, Gauss-Markov) and the
nominal's integration scheme (Euler, trapezoid) become the discrete error model of
:mod:`kalcal.scenarios.accel_gps.settings`; see that module's docstring for the choices.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from kalcal.models.settings import SettingError, show

if TYPE_CHECKING:
    from kalcal.scenarios.accel_gps.settings import AccelGpsTruth


def bias_discretization(values: AccelGpsTruth, step, period: float) -> tuple[np.ndarray, np.ndarray]:
    """The bias over accelerometer sample steps: b_{j+1} = phi_j b_j + n_j, n_j ~ N(0, q_j).

    The one discretization of the bias that the Monte Carlo's truth and filter and ``calibrate`` use. It
    is exact at the sample times, which are all the accelerometer (and so the nominal) ever sees of the
    bias: Gauss-Markov (tau > 0), phi_j = exp(-step_j / tau) and q_j = bias_std^2 (1 - exp(-2 step_j / tau)),
    which keeps the bias stationary with std ``bias_std`` over steps of any length; random walk,
    bias_walk_std^2 step_j / period (bias_walk_std is per sample of ``period`` s). Both may be set; their
    variances add. A constant bias: phi = 1, q = 0.

    Parameters
    ----------
    values : AccelGpsTruth
        The truth's or the filter's settings.
    step : float or ndarray, shape (...)
        Step lengths, s.
    period : float
        The nominal sample period, s, that ``bias_walk_std`` refers to.

    Returns
    -------
    decay, variance : ndarray, shape (...)
        phi_j (1) and q_j, (m/s^2)^2.
    """
    step = np.asarray(step, dtype=float)
    tau = values.bias_correlation_time
    variance = values.bias_walk_std**2 * (step / period)
    if tau > 0:
        return np.exp(-step / tau), variance - values.bias_std**2 * np.expm1(-2.0 * step / tau)
    return np.ones_like(step), variance


def error_transition(start, end, step, decay, scheme: str, closes=True) -> tuple[np.ndarray, np.ndarray]:
    """Transition of the error state [dp, dv, b] over a piece [start, end] of one sample step, and the
    weights of the bias's own noise n_j (:func:`bias_discretization`), which the step's closing sample draws.

    The nominal integrates the bias it reads at the samples as the scheme does: Euler holds b_j over the
    step, the trapezoid rule the line from b_j to b_{j+1} = phi b_j + n_j (so n_j also enters dp and dv of
    that step). Over the whole step (start 0, end = step) this is exact for the sampled truth::

        euler:      [[1, dt, -dt^2/2], [0, 1, -dt], [0, 0, phi]],                   n_j weights [0, 0, 1]
        trapezoid:  [[1, dt, -dt^2 (2 + phi)/6], [0, 1, -dt (1 + phi)/2], [0, 0, phi]],   [-dt^2/6, -dt/2, 1]

    (with a constant bias, phi = 1, both are the report's Phi). A piece cut by a GPS fix (``calibrate``)
    integrates the same line over its part of the step; b steps to phi b only in the piece that
    ``closes`` the step, and the other pieces take their share of n_j as noise of their own.

    Parameters
    ----------
    start, end : float or ndarray, shape (...)
        Offsets of the piece from the step's first sample, s (0 <= start < end <= step).
    step : float or ndarray, shape (...)
        The whole step's length, s.
    decay : float or ndarray, shape (...)
        phi of the step.
    scheme : {"euler", "trapezoid"}
    closes : bool or ndarray, shape (...)
        Whether the piece ends at the step's closing sample.

    Returns
    -------
    phi : ndarray, shape (..., 3, 3)
    bias_noise : ndarray, shape (..., 3)
        The piece's change of [dp, dv, b] per unit n_j.
    """
    u0, u1, step, decay = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (start, end, step, decay)))
    closes = np.broadcast_to(np.asarray(closes, dtype=bool), u0.shape)
    h = u1 - u0
    if scheme == "trapezoid":
        mean_slope, noise_slope = (decay - 1.0) / step, 1.0 / step  # b(u) = b_j (1 + mean_slope u) + n_j u / step
    elif scheme == "euler":
        mean_slope = noise_slope = np.zeros_like(h)
    else:
        raise SettingError("scenario.integration", "one of euler, trapezoid", show(scheme))
    first = 0.5 * (u1 * u1 - u0 * u0)  # integral of u over the piece
    second = h * h * (3.0 * u0 + h) / 6.0  # integral of (end - u) u over the piece
    phi = np.zeros(h.shape + (3, 3))
    phi[..., 0, 0] = phi[..., 1, 1] = 1.0
    phi[..., 0, 1] = h
    phi[..., 0, 2] = -(0.5 * h * h + mean_slope * second)
    phi[..., 1, 2] = -(h + mean_slope * first)
    phi[..., 2, 2] = np.where(closes, decay, 1.0)
    noise = np.stack([-noise_slope * second, -noise_slope * first, closes.astype(float)], axis=-1) + 0.0  # no -0.0
    return phi, noise
