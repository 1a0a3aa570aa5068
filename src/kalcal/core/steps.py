"""The numpy reference of the Kalman filter's steps: predict, the Joseph / standard updates, the covariance pass.

Every numpy filter of the package (the gain schedule, the regression filter, the calibration's loops,
the steady state, a Monte Carlo problem's mean-error prediction) calls these functions, or the square-root form's
steps in :mod:`kalcal.core.sqrt_form` (:func:`~kalcal.core.sqrt_form.sqrt_predict`,
:func:`~kalcal.core.sqrt_form.sqrt_update`); :func:`kalcal.filters.gains.run_with_gains` applies the
covariance pass's gains to the states with products alone, and is tested against :func:`predict` and
:func:`update` step by step. The compiled kernels are tested against these steps update by update: the
one compiled covariance update they share (:func:`kalcal.core.kernels.covariance_update`, against
:func:`gain_and_covariance` in tests/core/test_kernel_update.py), the sequential filter
(tests/filters/test_sequential.py), the composition of an interval's pieces
(tests/calibration/test_interval_model.py) and the Monte Carlo block kernels
(tests/montecarlo/test_kernel_steps.py; besides, their block sums against the numpy path).

Shapes: a state is ``(..., d)``, a covariance ``(..., d, d)``, a measurement ``(..., p)`` and a
measurement matrix ``(p, d)`` (shared) or ``(..., p, d)`` (one per realization): the caller says which
by the array it passes, and every function broadcasts over the leading (batch) axes with ``@``. A scalar
measurement is p = 1: z of shape ``(..., 1)`` and a row H of shape ``(..., 1, d)``.

Equations (prior ``xbar, M``; posterior ``xhat, P``)::

    predict:  xbar = Phi xhat,   M = Phi P Phi^T + Q                  (Phi = None: Phi = I, a random walk)
    update:   r = z - H xbar,    S = H M H^T + V,    K = M H^T S^{-1},    xhat = xbar + K r
              P = (I - K H) M (I - K H)^T + K V K^T        (form="joseph", the default)
              P = M - K H M                                (form="standard")

The normalized innovation squared (:func:`nis`), NIS = r^T S^{-1} r, is computed here once for every
numpy path of the package (the Monte Carlo's reference blocks, the calibrations' diagnostics and gates,
the likelihood); :func:`summed_nis` is its sum over realizations that share S, from their outer products.
The compiled paths that compute a NIS are held to :func:`nis`: the sequential filter's gate
(tests/filters/test_sequential.py), the data-dependent (regression) block kernel
(tests/montecarlo/test_kernel_steps.py), the fixed-gain block kernels through :func:`summed_nis`
(tests/montecarlo/test_engine.py) and the compiled diffuse likelihood (in tests/fitting, step by step
against the diffuse start of :mod:`kalcal.core.diffuse` and the regression filter).

The covariance pass (:func:`covariance_pass`) runs the covariance halves of these steps without data
over a time-invariant model's update intervals (:func:`interval_transition`), in any of the three forms.

Missing measurements (:mod:`kalcal.core.missing`). A realization whose measurement has a non-finite
component, or whose own H holds one, is not updated: xhat = xbar and P = M, with K = 0 and the residual
r and S NaN. :func:`update` and :func:`~kalcal.core.sqrt_form.sqrt_update` do this realization by
realization through one wrapper (:func:`kalcal.core.missing.update_where_measured`), so no numpy
filter handles a missing value its own way. Elsewhere: the compiled sequential filter and the compiled diffuse
likelihood apply the same rule (:func:`kalcal.core.kernels.measured`),
:func:`~kalcal.filters.gains.run_with_gains` refuses a missing value (its gains assume every update), and
the Monte Carlo kernels are never given one (simulated data are finite).
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import numpy as np

from kalcal.core.missing import update_where_measured
from kalcal.core.model import LinearGaussianModel
from kalcal.core.sqrt_form import cholesky_factor, gram, interval_noise_factor, sqrt_gain_and_factor, sqrt_predict
from kalcal.errors import ConfigError
from kalcal.linalg import matvec, symmetrize

UpdateForm = Literal["joseph", "standard", "sqrt"]
UPDATE_FORMS: tuple[str, ...] = ("joseph", "standard", "sqrt")
#: forms that map a covariance to a covariance (:func:`gain_and_covariance`, :func:`update`); "sqrt"
#: carries a factor instead (:func:`~kalcal.core.sqrt_form.sqrt_predict`,
#: :func:`~kalcal.core.sqrt_form.sqrt_update`)
COVARIANCE_FORMS: tuple[str, ...] = ("joseph", "standard")


def check_form(form: str, name: str = "form") -> None:
    """Raise :class:`ConfigError` naming ``name`` unless ``form`` is one of :data:`UPDATE_FORMS`."""
    if form not in UPDATE_FORMS:
        raise ConfigError(f"{name}: expected one of {', '.join(UPDATE_FORMS)}, got {form!r}")


def predict_covariance(cov: np.ndarray, phi: np.ndarray | None, q: np.ndarray) -> np.ndarray:
    """The covariance half of a prediction: M = Phi P Phi^T + Q, symmetrized.

    Parameters
    ----------
    cov : ndarray, shape (..., d, d)
        Posterior covariance P.
    phi : ndarray, shape (d, d) or (..., d, d), or None
        Transition; None is the identity (a random walk), which skips the two products.
    q : ndarray, shape (d, d) or (..., d, d)
        Process-noise covariance over the step.

    Returns
    -------
    ndarray, shape (..., d, d)
    """
    if phi is None:
        return symmetrize(cov + q)
    return symmetrize(phi @ cov @ np.swapaxes(phi, -1, -2) + q)


def predict(
    x: np.ndarray, cov: np.ndarray, phi: np.ndarray | None, q: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Propagate a state estimate and its covariance: xbar = Phi x, M = Phi P Phi^T + Q.

    Parameters
    ----------
    x : ndarray, shape (..., d)
    cov : ndarray, shape (..., d, d)
    phi : ndarray, shape (d, d) or (..., d, d), or None (the identity: xbar = x, M = P + Q)
    q : ndarray, shape (d, d) or (..., d, d)

    Returns
    -------
    xbar : ndarray, shape (..., d)
    prior_cov : ndarray, shape (..., d, d)
    """
    xbar = x if phi is None else matvec(phi, x)
    return xbar, predict_covariance(cov, phi, q)


def interval_transition(phi: np.ndarray, gamma: np.ndarray, w: np.ndarray, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Transition and process-noise covariance over ``steps`` samples.

    Phi_m = Phi^m and Q_m = sum_{i=0}^{m-1} Phi^i Gamma W Gamma^T (Phi^i)^T, so that
    x_{j+m} = Phi_m x_j + (noise ~ N(0, Q_m)) exactly: Q_m is m predictions of the covariance
    (:func:`~kalcal.core.steps.predict_covariance`) from Q_0 = 0.

    Parameters
    ----------
    phi : ndarray, shape (d, d)
    gamma : ndarray, shape (d, q)
    w : ndarray, shape (q, q)
    steps : int, m >= 0

    Returns
    -------
    phi_m : ndarray, shape (d, d)
    q_m : ndarray, shape (d, d), symmetric
    """
    d = phi.shape[0]
    phi_m = np.eye(d)
    q_m = np.zeros((d, d))
    step_noise = gamma @ w @ gamma.T
    for _ in range(int(steps)):
        q_m = predict_covariance(q_m, phi, step_noise)
        phi_m = phi @ phi_m
    return phi_m, q_m


class UpdateResult(NamedTuple):
    """One measurement update. Shapes follow the inputs' leading axes."""

    x: np.ndarray  #: posterior state, (..., d)
    cov: np.ndarray  #: posterior covariance P, (..., d, d)
    residual: np.ndarray  #: innovation r = z - H xbar, (..., p); NaN where the measurement is missing
    innovation_cov: np.ndarray  #: S = H M H^T + V, (..., p, p); NaN where the measurement is missing
    gain: np.ndarray  #: K, (..., d, p); 0 where the measurement is missing


def gain_and_covariance(
    cov: np.ndarray, h: np.ndarray, v: np.ndarray, form: UpdateForm = "joseph"
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The covariance half of an update, which needs no measurement.

    S = H M H^T + V, K = M H^T S^{-1} (by a solve with S: K^T = S^{-1} H M; a division where p = 1), and
    P = (I - K H) M (I - K H)^T + K V K^T (Joseph) or P = M - K H M (standard).

    Parameters
    ----------
    cov : ndarray, shape (..., d, d)
        Prior covariance M.
    h : ndarray, shape (p, d) or (..., p, d)
    v : ndarray, shape (p, p) or (..., p, p)
    form : {"joseph", "standard"}
        ("sqrt" carries a factor, not a covariance: :func:`~kalcal.core.sqrt_form.sqrt_gain_and_factor`)

    Returns
    -------
    gain : ndarray, shape (..., d, p)
        K = M H^T S^{-1}, computed by a solve with S (a division for a scalar measurement).
    posterior_cov : ndarray, shape (..., d, d)
    innovation_cov : ndarray, shape (..., p, p)
    """
    if form == "sqrt":
        raise ConfigError(
            "form: 'sqrt' carries a factor of the covariance, not the covariance: use sqrt_predict and "
            "sqrt_update (or covariance_pass(form='sqrt'))"
        )
    if form not in COVARIANCE_FORMS:
        raise ConfigError(f"form: expected one of {', '.join(COVARIANCE_FORMS)}, got {form!r}")
    ht = np.swapaxes(h, -1, -2)
    hm = h @ cov
    s = symmetrize(hm @ ht + v)
    # K^T = S^{-1} H M, because S and M are symmetric; for a scalar measurement (p = 1) S^{-1} is a
    # division, which costs a hundredth of a batched 1 x 1 solve.
    gain = np.swapaxes(hm / s if s.shape[-1] == 1 else np.linalg.solve(s, hm), -1, -2)
    if form == "joseph":
        i_kh = np.eye(cov.shape[-1]) - gain @ h
        posterior = i_kh @ cov @ np.swapaxes(i_kh, -1, -2) + gain @ v @ np.swapaxes(gain, -1, -2)
    else:
        posterior = cov - gain @ hm
    return gain, symmetrize(posterior), s


def update(
    x: np.ndarray,
    cov: np.ndarray,
    z: np.ndarray,
    h: np.ndarray,
    v: np.ndarray,
    form: UpdateForm = "joseph",
) -> UpdateResult:
    """Measurement update of a prior (xbar, M) with measurement z.

    A realization whose z (or own H) has a non-finite component keeps its prior: xhat = xbar, P = M,
    K = 0, r and S NaN (a missing measurement is a prediction only).

    Parameters
    ----------
    x : ndarray, shape (..., d)
    cov : ndarray, shape (..., d, d)
    z : ndarray, shape (..., p)
    h : ndarray, shape (p, d) or (..., p, d)
    v : ndarray, shape (p, p) or (..., p, p)
    form : {"joseph", "standard"}
    """
    return update_where_measured(_update_every, x, cov, z, h, v, form)


def _update_every(x, cov, z, h, v, form) -> UpdateResult:
    """:func:`update` of every realization, its z and H finite."""
    gain, posterior, s = gain_and_covariance(cov, h, v, form)
    residual = z - matvec(h, x)
    return UpdateResult(x + matvec(gain, residual), posterior, residual, s, gain)


def nis(innovation: np.ndarray, innovation_cov: np.ndarray | None = None) -> np.ndarray:
    """The normalized innovation squared, NIS = r^T S^{-1} r, of each innovation.

    chi-square(m) for a consistent filter's innovation r ~ N(0, S).

    Parameters
    ----------
    innovation : ndarray, shape (..., m)
        r = z - H xbar, in the measurement's units; or, with ``innovation_cov`` None, the normalized
        innovation L^{-1} r (S = L L^T, dimensionless), whose NIS is its squared norm.
    innovation_cov : ndarray, shape (..., m, m), or None
        S, symmetric positive definite, broadcast against ``innovation``'s leading (batch) axes.

    Returns
    -------
    ndarray, shape (...)
        Dimensionless; NaN where r or S is NaN (a missing measurement).

    Notes
    -----
    m = 1 is a division and m = 2 the closed form (b r_1^2 - 2 c r_1 r_2 + a r_2^2) / (a b - c^2) of
    S = [[a, c], [c, b]] (a tenth of a batched solve's time; the likelihood evaluates it for every fix of
    every fit's step); otherwise |L^{-1} r|^2 by a Cholesky factor and a triangular solve, never an inverse.
    """
    r = np.asarray(innovation, dtype=float)
    if innovation_cov is None:
        return np.sum(r * r, axis=-1)
    s = np.asarray(innovation_cov, dtype=float)
    m = r.shape[-1]
    if s.shape[-2:] != (m, m):
        raise ValueError(f"innovation_cov: expected shape (..., {m}, {m}) for innovations (..., {m}), got {s.shape}")
    if m == 1:
        return r[..., 0] * r[..., 0] / s[..., 0, 0]
    if m == 2:
        a, b, c = s[..., 0, 0], s[..., 1, 1], 0.5 * (s[..., 0, 1] + s[..., 1, 0])
        r1, r2 = r[..., 0], r[..., 1]
        return (b * r1 * r1 - 2.0 * c * r1 * r2 + a * r2 * r2) / (a * b - c * c)
    lower = np.linalg.cholesky(s)
    white = np.linalg.solve(lower, r[..., None])[..., 0]
    return np.sum(white * white, axis=-1)


def summed_nis(residual_outer: np.ndarray, innovation_cov: np.ndarray) -> np.ndarray:
    """sum_i r_i^T S^{-1} r_i = tr(S^{-1} sum_i r_i r_i^T): the sum of :func:`nis` over realizations that share S.

    Parameters
    ----------
    residual_outer : ndarray, shape (..., m, m)
        sum_i r_i r_i^T over the realizations, in the measurement's units squared.
    innovation_cov : ndarray, shape (..., m, m)
        S, shared by the realizations, symmetric positive definite.

    Returns
    -------
    ndarray, shape (...)
        Dimensionless.

    Notes
    -----
    The same sizes take the same paths as :func:`nis` (m = 1 a division, m = 2 the closed form of S^{-1}),
    so that a Monte Carlo block's sums cost no batched solve; otherwise a solve with S, never an inverse.
    """
    s = np.asarray(innovation_cov, dtype=float)
    outer = np.asarray(residual_outer, dtype=float)
    m = s.shape[-1]
    if outer.shape[-2:] != (m, m):
        raise ValueError(f"residual_outer: expected shape (..., {m}, {m}) for innovation_cov (..., {m}, {m}), got {outer.shape}")
    if m == 1:
        return outer[..., 0, 0] / s[..., 0, 0]
    if m == 2:
        a, b, c = s[..., 0, 0], s[..., 1, 1], 0.5 * (s[..., 0, 1] + s[..., 1, 0])
        return (b * outer[..., 0, 0] - c * (outer[..., 0, 1] + outer[..., 1, 0]) + a * outer[..., 1, 1]) / (a * b - c * c)
    return np.trace(np.linalg.solve(s, outer), axis1=-2, axis2=-1)


class GainSchedule(NamedTuple):
    """Every gain and covariance of a time-invariant model, computed before any data.

    Index k = 0..K-1 is the k-th measurement update, at sample (k + 1) * steps_per_update.
    """

    prior_cov: np.ndarray  #: M_k, (K, d, d)
    posterior_cov: np.ndarray  #: P_k, (K, d, d)
    gain: np.ndarray  #: K_k, (K, d, p)
    innovation_cov: np.ndarray  #: S_k, (K, p, p)
    phi_interval: np.ndarray  #: Phi^m, (d, d), of the model without its time-varying part
    q_interval: np.ndarray  #: Q_m, (d, d)
    transitions: np.ndarray  #: the transition over each interval, (K, d, d) (Phi^m repeated if time-invariant)


def covariance_pass(
    model: LinearGaussianModel, n_updates: int, form: UpdateForm = "joseph", transitions: np.ndarray | None = None
) -> GainSchedule:
    """Riccati recursion alone: M_{k} = Phi_k P_{k-1} Phi_k^T + Q_m, then the update, K times.

    P_{-1} is the prior covariance M0 at sample 0. Phi_k is Phi^m for a time-invariant model, or
    ``transitions[k]`` (K, d, d) when the caller gives the transition of each interval explicitly (a
    transition that depends on a known input, such as a column of a sensor reading; the
    process noise Q_m must not depend on it). ``form="sqrt"`` carries L with P = L L^T instead
    (:func:`~kalcal.core.sqrt_form.sqrt_predict`, :func:`~kalcal.core.sqrt_form.sqrt_gain_and_factor`,
    the interval noise by :func:`~kalcal.core.sqrt_form.interval_noise_factor`); the schedule holds the
    covariances L L^T all the same.
    """
    check_form(form)
    phi_m, q_m = interval_transition(model.phi, model.gamma, model.w, model.steps_per_update)
    d, p = model.state_dim, model.measurement_dim
    if transitions is None:
        transitions = np.broadcast_to(phi_m, (n_updates, d, d))
    elif transitions.shape != (n_updates, d, d):
        raise ValueError(f"transitions: expected shape {(n_updates, d, d)}, got {transitions.shape}")
    prior = np.empty((n_updates, d, d))
    posterior = np.empty((n_updates, d, d))
    gains = np.empty((n_updates, d, p))
    innovation = np.empty((n_updates, p, p))
    if form == "sqrt":
        q_chol = interval_noise_factor(model.phi, model.gamma, model.w, model.steps_per_update)
        v_chol = cholesky_factor(model.v)
        chol = cholesky_factor(model.m0)
        for k in range(n_updates):
            _, chol = sqrt_predict(np.zeros(d), chol, transitions[k], q_chol)
            prior[k] = gram(chol)
            gains[k], chol, s_chol = sqrt_gain_and_factor(chol, model.h, v_chol)
            posterior[k], innovation[k] = gram(chol), gram(s_chol)
        return GainSchedule(prior, posterior, gains, innovation, phi_m, q_m, transitions)
    cov = model.m0
    for k in range(n_updates):
        cov = predict_covariance(cov, transitions[k], q_m)
        prior[k] = cov
        gains[k], cov, innovation[k] = gain_and_covariance(cov, model.h, model.v, form)
        posterior[k] = cov
    return GainSchedule(prior, posterior, gains, innovation, phi_m, q_m, transitions)
