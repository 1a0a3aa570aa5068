"""The static-pose model of a 3-axis accelerometer: a_i = M f_i + b + n_i, its faces and its parameters.

Conventions (docs/imu-3axis.md):

* f_i, m/s^2, is the specific force at rest in the sensor frame: it points **up**, |f_i| = g. With the
  x axis up (face ``x_p``) an ideal sensor reads +g on x; with it down (``x_a``) -g.
* M (3, 3, dimensionless) maps the specific force to the readings: row k is axis k's sensitivity
  direction times its scale, so the scale factor of axis k is the norm of row k. b (3,), m/s^2, the biases.
  The correction a user applies to a reading a_m is a = M^-1 (a_m - b) (m/s^2).
* Procedure (b)'s parameters (9): M = S T with S = diag(s_x, s_y, s_z) and T lower-triangular with unit
  rows: the sensor's x axis fixes the frame, its y axis lies in the frame's x-y plane::

      T = [[1,        0,                 0               ],
           [sin a0,   cos a0,            0               ],
           [sin a1,   cos a1 sin a2,     cos a1 cos a2   ]]

  a0 the y axis's tilt toward x, a1 the z axis's toward x, a2 the z axis's toward y (rad); the
  parameter vector is ``PARAM_NAMES`` = (s_x, s_y, s_z, a0, a1, a2, b_x, b_y, b_z).
* A pose's orientation is its up direction, given as a nominal unit vector n (3,) and 2 tilt angles
  (tangent coordinates d1, d2 on the basis t1, t2 perpendicular to n, :func:`tangent_basis`):
  f = g (n + d1 t1 + d2 t2) / sqrt(1 + d1^2 + d2^2), a tilt of arctan(|d|) from n, smooth at d = 0
  (no gimbal lock at any face).

:func:`h` is written with :mod:`kalcal.core.xmath`, so the same definition serves numpy batches, sympy's
Jacobians and the nonlinear filters (state: the 9 parameters and a pose's 2 tilts; data: the pose's n, t1, t2).
"""

from __future__ import annotations

import numpy as np

from kalcal.core import xmath as xm

#: g, m/s^2: the standard gravity (a setting, ``scenario.gravity``)
STANDARD_GRAVITY = 9.80665
#: procedure (b)'s parameters, in the state's order, and their units
PARAM_NAMES = ("scale_x", "scale_y", "scale_z", "misalignment_yx", "misalignment_zx", "misalignment_zy", "bias_x", "bias_y", "bias_z")
PARAM_UNITS = ("1", "1", "1", "rad", "rad", "rad", "m/s^2", "m/s^2", "m/s^2")
#: the six faces (imucal's names): which axis points up (+1) or down (-1)
FACES = {"x_p": (0, 1.0), "x_a": (0, -1.0), "y_p": (1, 1.0), "y_a": (1, -1.0), "z_p": (2, 1.0), "z_a": (2, -1.0)}
AXES = ("x", "y", "z")


def face_up(name: str) -> np.ndarray:
    """The up direction (3,) in the sensor frame of face ``name`` (``x_p``: +x up, the x reading +g)."""
    axis, sign = FACES[name]
    up = np.zeros(3)
    up[axis] = sign
    return up


def tangent_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors t1, t2 (each (..., 3)) perpendicular to the unit vector(s) ``n`` and to each other,
    (n, t1, t2) right-handed: the axes of a pose's 2 tilt angles."""
    n = np.asarray(n, dtype=float)
    # the helper axis is the one least aligned with n, so the cross product never degenerates
    helper = np.zeros_like(n)
    index = np.argmin(np.abs(n), axis=-1)
    np.put_along_axis(helper, index[..., None], 1.0, axis=-1)
    t1 = np.cross(helper, n)
    t1 /= np.linalg.norm(t1, axis=-1, keepdims=True)
    return t1, np.cross(n, t1)


def misalignment_matrix(angles):
    """T (3, 3) of the 3 misalignment angles (rad), or (n, 3, 3) for (n, 3); any xmath kind."""
    a0, a1, a2 = angles[..., 0], angles[..., 1], angles[..., 2]
    zero, one = 0.0 * a0, 0.0 * a0 + 1.0
    rows = [xm.stack([one, zero, zero]), xm.stack([xm.sin(a0), xm.cos(a0), zero]),
            xm.stack([xm.sin(a1), xm.cos(a1) * xm.sin(a2), xm.cos(a1) * xm.cos(a2)])]
    return xm.stack(rows, axis=-2)


def sensor_matrix(params) -> np.ndarray:
    """M = S T (3, 3) of the 9 parameters (or (n, 3, 3) of (n, 9)), numpy."""
    params = np.asarray(params, dtype=float)
    return params[..., :3, None] * misalignment_matrix(params[..., 3:6])


def params_of(M: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The 9 parameters of a sensor matrix whose rows are as :data:`PARAM_NAMES` says (row x along +x, row y
    in the x-y plane): the inverse of :func:`sensor_matrix` (scales are the row norms)."""
    M = np.asarray(M, dtype=float)
    scale = np.linalg.norm(M, axis=1)
    T = M / scale[:, None]
    a0 = np.arctan2(T[1, 0], T[1, 1])
    a1 = np.arcsin(np.clip(T[2, 0], -1, 1))
    a2 = np.arctan2(T[2, 1], T[2, 2])
    return np.concatenate([scale, [a0, a1, a2], np.asarray(b, dtype=float)])


def up_direction(tilts, data):
    """The pose's unit up vector (n, 3) from its tangent tilts (n, 2) and ``data`` = [n, t1, t2] (9,) or (n, 9)."""
    d1, d2 = tilts[..., 0], tilts[..., 1]
    norm = xm.sqrt(1.0 + d1 * d1 + d2 * d2)
    return xm.stack([(data[..., k] + d1 * data[..., 3 + k] + d2 * data[..., 6 + k]) / norm for k in range(3)])


def h(x, data, gravity: float = STANDARD_GRAVITY):
    """A pose's mean reading (n, 3), m/s^2: M(params) f + b with f = g * the up direction of its tilts.

    Parameters
    ----------
    x : array (n, 11)
        The 9 parameters (:data:`PARAM_NAMES`) and the pose's 2 tilt angles (rad, tangent coordinates);
        numpy floats, sympy symbols (dtype object) or jax arrays (:mod:`kalcal.core.xmath`).
    data : array (9,) or (n, 9)
        The pose's nominal up direction n and its tangent basis t1, t2 (:func:`pose_data`).
    gravity : float
        g, m/s^2.
    """
    f = up_direction(x[..., 9:11], data) * gravity
    T = misalignment_matrix(x[..., 3:6])
    return xm.stack([x[..., 6 + k] + x[..., k] * (T[..., k, 0] * f[..., 0] + T[..., k, 1] * f[..., 1] + T[..., k, 2] * f[..., 2])
                     for k in range(3)])


def pose_data(up: np.ndarray) -> np.ndarray:
    """[n, t1, t2] (..., 9) of nominal up direction(s) ``up`` (normalized here): what :func:`h` takes as data."""
    n = np.asarray(up, dtype=float)
    n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    t1, t2 = tangent_basis(n)
    return np.concatenate([n, t1, t2], axis=-1)


def correct(readings: np.ndarray, M: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The corrected specific force a = M^-1 (a_m - b) (n, 3), m/s^2, of readings a_m (n, 3), m/s^2 (a solve, not an inverse)."""
    readings = np.atleast_2d(np.asarray(readings, dtype=float))
    return np.linalg.solve(M, (readings - b).T).T


def random_tilts(rng: np.random.Generator, n: int, bound: float) -> np.ndarray:
    """``n`` tilts (n, 2) in tangent coordinates, uniform over the spherical cap of half-angle ``bound``
    (rad) around the nominal direction: the truth's unknown fixture error in the tests."""
    cos_angle = rng.uniform(np.cos(bound), 1.0, n)  # uniform on the cap's area
    angle = np.arccos(cos_angle)
    phi = rng.uniform(0, 2 * np.pi, n)
    r = np.tan(angle)
    return np.column_stack([r * np.cos(phi), r * np.sin(phi)])
