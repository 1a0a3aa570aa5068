"""GPS fixes drawn from the fitted accel-gps filter over a given log: the parametric bootstrap's logs.

The accel-gps likelihood sees the log only through the fixes' differences from the nominal trajectory that
the accelerometer integrates, dz_k = z_k - nominal(t_k - L) (:func:`~kalcal.scenarios.accel_gps.evaluation.build_inputs`):
the accelerometer enters through that nominal and through the intervals' transitions and noise, which the
prepared log holds. The truth's motion behind the log is not known and is not needed: under the fitted
model the error state x = truth - nominal follows the filter's own linear model,

    x_0 ~ N(0, M_0),   x_k = Phi_k x_{k-1} + w_k (w_k ~ N(0, Q_k)),   dz_k = H x_k + v_k (v_k ~ N(0, V_k)),

with Phi_k, Q_k, H, V_k and M_0 those of the fitted settings, on the log's own accelerometer sample times and
fix times. A drawn log is the user's log with each used fix replaced by nominal + dz_k: the accelerometer
samples, the fix times, the fixes left out (a NaN field, outside the accelerometer log), the per-fix std
columns and the first fix that anchors the nominal (``init="first-fix"``) are held; only the fixes' values
are drawn. A diffuse bias (its prior 1-sigma :data:`~kalcal.scenarios.accel_gps.evaluation.DIFFUSE_BIAS_STD`)
starts at 0: the conditional likelihood, given the first fix, does not depend on where it starts.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from kalcal.scenarios.accel_gps import evaluation

if TYPE_CHECKING:
    from kalcal.scenarios.accel_gps.log import AccelGpsLog


def _factors(covariances: np.ndarray) -> np.ndarray:
    """A factor F_k with F_k F_k^T = C_k for each symmetric PSD C_k (eigen-decomposition: Q_k of a bias
    walk of 0 is singular, where Cholesky fails), shape (K, d, d)."""
    symmetric = 0.5 * (covariances + np.swapaxes(covariances, -1, -2))
    values, vectors = np.linalg.eigh(symmetric)
    return vectors * np.sqrt(np.clip(values, 0.0, None))[..., None, :]


def simulate_fixes(log: AccelGpsLog, values: Mapping[str, float], rng: np.random.Generator) -> AccelGpsLog:
    """``log`` with its used fixes drawn from the filter at ``values`` over its settings (module docstring).

    Parameters
    ----------
    log : AccelGpsLog
        The prepared user's log.
    values : mapping of str to float
        The fitted settings as :meth:`AccelGpsLog.loglik` takes them (per-sample keys); the others are the log's.
    rng : numpy.random.Generator
        Draws in a fixed order whatever the settings: x_0 (d,), then the process noise (K, d), then the
        fixes' noise (K, 2).

    Returns
    -------
    AccelGpsLog
        The same log with ``z_position`` (m) and ``z_velocity`` (m/s), shape (K,) each, drawn; a velocity-only
        log's positions stay NaN.
    """
    resolved = evaluation.resolve(log, values)
    inputs = evaluation.build_inputs(log, resolved, set(values))
    d = inputs.x0.shape[0]
    m0 = inputs.m0.copy()
    if inputs.bias_prior_std == evaluation.DIFFUSE_BIAS_STD:
        # a diffuse bias starts at 0 (module docstring): its prior's term bias0^2 g g^T leaves M_0, g the
        # bias's column of the map to the start (a latency's Phi_L with init first-fix, else the unit vector)
        lat = resolved["filter.gps_latency"]
        g = np.zeros(d)
        g[:3] = evaluation.latency_map(lat)[1][:, 2] if log.init == "first-fix" and lat != 0.0 else np.eye(3)[2]
        m0 -= inputs.bias_prior_std**2 * np.outer(g, g)
    x = inputs.x0 + _factors(m0[None])[0] @ rng.standard_normal(d)
    process = np.einsum("kij,kj->ki", _factors(inputs.qs), rng.standard_normal((log.fixes, d)))
    fix_noise = rng.standard_normal((log.fixes, 2))
    states = np.empty((log.fixes, d))
    for k in range(log.fixes):
        x = inputs.phis[k] @ x + process[k]
        states[k] = x
    rows = list(log.fix_states)
    dz = states @ inputs.h.T + np.sqrt(np.einsum("kii->ki", inputs.vs)) * fix_noise[:, rows]
    described_p, described_v = log.nominal(resolved["filter.gps_latency"])[:2]
    z_velocity = described_v + dz[:, rows.index(1)]
    z_position = described_p + dz[:, 0] if 0 in rows else log.z_position
    return replace(log, z_position=z_position, z_velocity=z_velocity)
