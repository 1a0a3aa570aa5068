"""accel-gps's integration of accelerometer samples into a nominal position and velocity (the strapdown step).

Schemes, for samples a_j at t_j with step dt_j = t_{j+1} - t_j::

    euler (the report):  v_{j+1} = v_j + a_j dt_j
                         p_{j+1} = p_j + v_j dt_j + a_j dt_j^2 / 2
    trapezoid:           v_{j+1} = v_j + (a_j + a_{j+1}) dt_j / 2
                         p_{j+1} = p_j + v_j dt_j + (2 a_j + a_{j+1}) dt_j^2 / 6

Euler holds each sample over the step that follows it, which lags the signal by half a sample. The
trapezoid scheme integrates the straight line between two samples exactly (twice), which removes that
lag and lets a step be cut anywhere (:func:`partial_step`) consistently with the whole step. Both are
exact for a constant acceleration, so a constant bias enters both exactly as the filter's model says.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from kalcal.models.settings import SettingError, show

Scheme = Literal["euler", "trapezoid"]
SCHEMES: tuple[str, ...] = ("euler", "trapezoid")


def _step_accel(accel: np.ndarray, scheme: str) -> tuple[np.ndarray, np.ndarray]:
    """Per step: the mean acceleration (velocity gain / dt) and the position gain beyond v dt, over dt^2."""
    if scheme == "euler":
        held = accel[..., :-1]
        return held, 0.5 * held
    if scheme == "trapezoid":
        start, end = accel[..., :-1], accel[..., 1:]
        return 0.5 * (start + end), (2.0 * start + end) / 6.0
    raise SettingError("scenario.integration", f"one of {', '.join(SCHEMES)}", show(scheme))


def integrate(
    accel: np.ndarray,
    dt: float | np.ndarray,
    p0: float | np.ndarray,
    v0: float | np.ndarray,
    scheme: Scheme = "euler",
) -> tuple[np.ndarray, np.ndarray]:
    """Integrate samples into position and velocity at every sample time.

    Parameters
    ----------
    accel : ndarray, shape (..., J + 1)
        Accelerometer samples a_0 .. a_J, m/s^2 (Euler does not use a_J).
    dt : float or ndarray, shape (J,)
        Step lengths, s.
    p0, v0 : float or ndarray, shape (...)
        Position (m) and velocity (m/s) at sample 0.
    scheme : {"euler", "trapezoid"}

    Returns
    -------
    position, velocity : ndarray, shape (..., J + 1)
        The recursion above, evaluated with cumulative sums (equal to a loop over samples up to the
        rounding of the order of additions).
    """
    accel = np.asarray(accel, dtype=float)
    step, step_position = _step_accel(accel, scheme)
    dt = np.broadcast_to(np.asarray(dt, dtype=float), step.shape[-1:])
    p0 = np.asarray(p0, dtype=float)[..., None]
    v0 = np.asarray(v0, dtype=float)[..., None]
    shape = np.broadcast_shapes(step.shape[:-1], p0.shape[:-1], v0.shape[:-1]) + (step.shape[-1] + 1,)
    # cumsum over [x_0, increment_0, increment_1, ...] adds the increments in the loop's order.
    velocity = np.empty(shape)
    velocity[..., :1] = v0
    velocity[..., 1:] = step * dt
    np.cumsum(velocity, axis=-1, out=velocity)
    position = np.empty(shape)
    position[..., :1] = p0
    position[..., 1:] = velocity[..., :-1] * dt + step_position * (dt * dt)
    np.cumsum(position, axis=-1, out=position)
    return position, velocity


def interval_weights(scheme: Scheme, dt: float, steps: int) -> np.ndarray:
    """Weights of the samples in the position and velocity gained over one interval of ``steps`` samples.

    Over samples s .. s + m (m = steps), with the nominal starting from rest at the origin,
    [p, v]_{s+m} = sum_{i=0}^{m} C[i] a_{s+i}: the integration scheme written as a linear map, found by
    integrating unit impulses.

    Returns
    -------
    ndarray, shape (m + 1, 2)
        C[:, 0] in m per (m/s^2), C[:, 1] in m/s per (m/s^2); C[m] is zero for Euler.
    """
    impulses = np.eye(steps + 1)
    position, velocity = integrate(impulses, dt, 0.0, 0.0, scheme)
    return np.stack([position[:, -1], velocity[:, -1]], axis=-1)


def partial_step(
    accel_start: np.ndarray,
    accel_end: np.ndarray,
    step: np.ndarray,
    into: np.ndarray,
    position: np.ndarray,
    velocity: np.ndarray,
    scheme: Scheme = "euler",
) -> tuple[np.ndarray, np.ndarray]:
    """Position and velocity a time ``into`` (0 <= into <= step) after a sample, inside its step.

    Euler holds a_j; trapezoid integrates the line from a_j to a_{j+1}. At ``into = step`` both give
    the whole step of :func:`integrate`. All arguments broadcast; times in s, SI units.
    """
    tau = np.asarray(into, dtype=float)
    if scheme == "euler":
        slope = 0.0
    elif scheme == "trapezoid":
        slope = (np.asarray(accel_end) - np.asarray(accel_start)) / np.asarray(step, dtype=float)
    else:
        raise SettingError("scenario.integration", f"one of {', '.join(SCHEMES)}", show(scheme))
    return (
        position + velocity * tau + accel_start * (0.5 * tau * tau) + slope * (tau**3 / 6.0),
        velocity + accel_start * tau + slope * (0.5 * tau * tau),
    )
