"""The state recursion of a gain schedule: a batch of measurement sequences filtered with precomputed gains.

The schedule (M_k, P_k, K_k, S_k of every update) comes from the covariance pass,
:func:`kalcal.core.steps.covariance_pass`; with it, each update is products alone.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from kalcal.core.steps import GainSchedule


class FilterRun(NamedTuple):
    """Estimates of a batch of realizations at every update. n realizations, K updates."""

    prior: np.ndarray  #: xbar_k, (n, K, d)
    posterior: np.ndarray  #: xhat_k, (n, K, d)
    residual: np.ndarray  #: r_k = z_k - H xbar_k, (n, K, p)


def run_with_gains(schedule: GainSchedule, h: np.ndarray, z: np.ndarray, x0: np.ndarray) -> FilterRun:
    """Run the state recursion with precomputed gains over a batch of measurement sequences.

    Parameters
    ----------
    schedule : GainSchedule
        From :func:`~kalcal.core.steps.covariance_pass`; its gains do not depend on the data.
    h : ndarray, shape (p, d)
    z : ndarray, shape (n, K, p)
        Measurements at the K updates.
    x0 : ndarray, shape (d,) or (n, d)
        Estimate at sample 0 (the prior mean).

    Every measurement must be present: the gains assume every update is made (a missing measurement
    changes the covariances after it, which :func:`kalcal.core.steps.update` handles, one step at a
    time).

    Raises
    ------
    ValueError
        If z has a non-finite (missing) value, naming the first one's realization and update. (One sum
        over z decides; the search for the culprit runs only when it is not finite.)
    """
    if not np.isfinite(np.sum(z)):
        i, k, _ = np.argwhere(~np.isfinite(z))[0]
        raise ValueError(
            f"z: measurement {z[i, k].tolist()} of realization {i} at update {k} is not finite; "
            "run_with_gains needs every measurement (its gains assume every update is made): filter data "
            "with missing values step by step with kalcal.core.steps.update"
        )
    n, n_updates, p = z.shape
    d = schedule.phi_interval.shape[0]
    prior = np.empty((n, n_updates, d))
    posterior = np.empty((n, n_updates, d))
    residual = np.empty((n, n_updates, p))
    x = np.broadcast_to(np.asarray(x0, dtype=float), (n, d))
    h_t = h.T
    for k in range(n_updates):
        xbar = x @ schedule.transitions[k].T
        r = z[:, k] - xbar @ h_t
        x = xbar + r @ schedule.gain[k].T
        prior[:, k], posterior[:, k], residual[:, k] = xbar, x, r
    return FilterRun(prior, posterior, residual)
