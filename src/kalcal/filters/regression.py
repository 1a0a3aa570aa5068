"""A Kalman filter for a regression with time-varying regressors, batched over realizations.

The parameters x follow a random walk (Phi = I) and each step brings one scalar measurement whose
regressor row h_k is data (it differs per realization and per step)::

    x_k = x_{k-1} + omega_{k-1},   omega ~ N(0, Q)            (Q = 0: constant parameters)
    y_k = h_k x_k + w_k,           w_k ~ N(0, R),   k = 1..K

    x_0 ~ N(x0, P0) is the estimate x_0^+ before the first measurement.

Each step is the time propagation x^- = x^+, P^- = P^+ + Q (the reference
:func:`kalcal.core.steps.predict` with Phi = I), then a measurement update by the reference
:func:`kalcal.core.steps.update` with p = 1: the row h_k as a (1, d) H, R as a (1, 1) V. Three update
forms give the same estimates in exact arithmetic:

* ``"joseph"``: the Joseph form (the package default);
* ``"standard"``: P^+ = P^- - K H P^-;
* ``"note"``: the calibration note's eqs. (14)-(18) for a scalar measurement,
  r = y - h x^-,  S = h P^- h^T + R,  K = P^- h^T / S,  P^+ = P^- - K (h P^-),  x^+ = x^- + K r,
  which are the standard form with p = 1: it runs as ``"standard"`` (K by a division by the scalar S).

A measurement that is NaN (or whose regressor row holds a NaN) is missing: as in every filter of the
package (:mod:`kalcal.core.steps`), that step is a prediction only, with r_k and S_k NaN.
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import numpy as np

from kalcal.core.missing import measured
from kalcal.core.steps import predict, update
from kalcal.errors import ConfigError

RegressionForm = Literal["joseph", "standard", "note"]
REGRESSION_FORMS: tuple[str, ...] = ("joseph", "standard", "note")


class ScalarUpdate(NamedTuple):
    """One scalar measurement update. Leading axes follow the inputs."""

    x: np.ndarray  #: x^+, (..., d)
    cov: np.ndarray  #: P^+, (..., d, d)
    residual: np.ndarray  #: r = y - h x^-, (...)
    innovation_var: np.ndarray  #: S = h P^- h^T + R, (...)
    gain: np.ndarray  #: K, (..., d)


def note_update(x: np.ndarray, cov: np.ndarray, y: np.ndarray, h: np.ndarray, r: float) -> ScalarUpdate:
    """The note's measurement update, eqs. (14)-(18), for one scalar measurement.

    r_k = y_k - h_k x^-;  S_k = h_k P^- h_k^T + R;  K_k = P^- h_k^T / S_k;
    P^+ = P^- - K_k (h_k P^-);  x^+ = x^- + K_k r_k: the standard form of the reference update with
    p = 1, which computes it.

    Parameters
    ----------
    x : ndarray, shape (..., d)
        Prior estimate x^-.
    cov : ndarray, shape (..., d, d)
        Prior covariance P^-.
    y : ndarray, shape (...)
        The measurement; NaN marks a missing one (the update keeps the prior).
    h : ndarray, shape (d,) or (..., d)
        The regressor row.
    r : float
        Measurement-noise variance R (the note's sigma_w^2).
    """
    return scalar_update(x, cov, y, h, r, "standard")


def scalar_update(
    x: np.ndarray, cov: np.ndarray, y: np.ndarray, h: np.ndarray, r: float, form: RegressionForm = "joseph"
) -> ScalarUpdate:
    """One update in the chosen form, by the reference :func:`kalcal.core.steps.update` with p = 1.

    ``"note"`` is the standard form (:func:`note_update`). Shapes as in :func:`note_update`; where y or
    h is not finite the prior is kept, with r and S NaN.
    """
    h_row = np.asarray(h, dtype=float)[..., None, :]  # (..., 1, d)
    result = update(
        x, cov, np.asarray(y, dtype=float)[..., None], h_row, np.array([[float(r)]]), "standard" if form == "note" else form
    )
    return ScalarUpdate(result.x, result.cov, result.residual[..., 0], result.innovation_cov[..., 0, 0], result.gain[..., 0])


class RegressionRun(NamedTuple):
    """A filter run over K steps. Leading axes ``...`` are the realizations (none for one series)."""

    prior: np.ndarray  #: x_k^-, (..., K, d)
    posterior: np.ndarray  #: x_k^+, (..., K, d)
    cov: np.ndarray  #: P_k^+, (..., K, d, d)
    residual: np.ndarray  #: r_k = y_k - h_k x_k^-, NaN where skipped, (..., K)
    innovation_var: np.ndarray  #: S_k = h_k P_k^- h_k^T + R, NaN where skipped, (..., K)
    used: np.ndarray  #: whether step k updated, bool (..., K)


def run_regression_filter(
    y: np.ndarray,
    h: np.ndarray,
    x0: np.ndarray,
    cov0: np.ndarray,
    r: float,
    q: np.ndarray,
    form: RegressionForm = "joseph",
) -> RegressionRun:
    """Filter K scalar measurements with time-varying regressors, for a batch of series at once.

    Parameters
    ----------
    y : ndarray, shape (..., K)
        Measurements y_k; NaN marks a missing one.
    h : ndarray, shape (..., K, d)
        Regressor rows h_k, always time-varying (a fixed row is passed repeated along K).
    x0 : ndarray, shape (d,) or (..., d)
        x_0^+, the estimate before the first measurement.
    cov0 : ndarray, shape (d, d) or (..., d, d)
        P_0^+.
    r : float
        Measurement-noise variance R > 0.
    q : ndarray, shape (d, d)
        Process-noise covariance Q per step (zeros for constant parameters).
    form : {"joseph", "standard", "note"}

    Returns
    -------
    RegressionRun
    """
    if form not in REGRESSION_FORMS:
        raise ConfigError(f"form: expected one of {', '.join(REGRESSION_FORMS)}, got {form!r}")
    y = np.asarray(y, dtype=float)
    h = np.asarray(h, dtype=float)
    lead, n_steps = y.shape[:-1], y.shape[-1]
    d = h.shape[-1]
    if h.shape[:-1] != y.shape:
        raise ValueError(f"h: expected shape {y.shape + (d,)} to match y {y.shape}, got {h.shape}")
    q = np.asarray(q, dtype=float)
    x = np.broadcast_to(np.asarray(x0, dtype=float), lead + (d,)).copy()
    cov = np.broadcast_to(np.asarray(cov0, dtype=float), lead + (d, d)).copy()
    used = measured(y[..., None], h[..., None, :])  # the one missing-measurement rule
    prior = np.empty(lead + (n_steps, d))
    posterior = np.empty(lead + (n_steps, d))
    covs = np.empty(lead + (n_steps, d, d))
    residual = np.empty(lead + (n_steps,))
    innovation = np.empty(lead + (n_steps,))
    for k in range(n_steps):
        # (9), (12): x^- = x^+, P^- = P^+ + Q (Phi = I).
        x, cov = predict(x, cov, None, q)
        prior[..., k, :] = x
        # (14)-(18); a missing y_k or h_k keeps the prior, with r_k and S_k NaN.
        step = scalar_update(x, cov, y[..., k], h[..., k, :], r, form)
        x, cov = step.x, step.cov
        residual[..., k], innovation[..., k] = step.residual, step.innovation_var
        posterior[..., k, :] = x
        covs[..., k, :, :] = cov
    return RegressionRun(prior, posterior, covs, residual, innovation, used)
