"""``kalcal verify imu-3axis``: procedure (b)'s estimators against a simulated truth, on the nonlinear bench.

**The truth.** Each realization draws the 9 parameters (:data:`~.model.PARAM_NAMES`) around their nominal
values (scales 1, no misalignment, no bias) with the stated prior standard deviations (``truth.scale_std``,
``truth.misalignment_std``, ``truth.bias_std``), independent and Gaussian, and each pose's orientation from
a Gaussian tilt in tangent coordinates (2 angles, each with standard deviation ``truth.tilt_spread``)
around the pose's nominal up direction (the layout, ``truth.layout``). Pose i gives one update, its mean
reading a_i = M f_i + b + n_i with n_i ~ N(0, sigma^2 I) (``truth.noise``, or ``truth.sample_noise`` /
sqrt(``truth.rate`` ``truth.pose_duration``)): K = the number of poses.

**The filters' state** (design choice): the 9 parameters and the *current* pose's 2 tilts, 11 states;
each pose's tilts are added at its update rather than all 9 + 2P up front. The transition keeps the 9
parameters and renews the tilts, f(x) = [theta, 0, 0] with Q = diag(0 (9), tilt_spread^2 I (2)): the
predict step sets the new pose's tilts to their prior (the nominal pose, the stated spread) uncorrelated
with the parameters, and the update sees them once. For the EKF and the IEKF this equals the
augmented 9 + 2P state exactly (a past pose's tilts never enter a later update, and a future pose's are
untouched until their own, so marginalizing them changes nothing); the UKF's sigma points differ (their
spread scales with the state's dimension), and 11 states keep it at 23 points whatever P.

**The checks are on the 9 parameters** (the tilts are nuisance states, each seen by one update); the
Cramér–Rao bound is the 9-parameter block of J^-1 of the joint information of (theta, the P poses' tilts)
with the tilts' prior, marginalized pose by pose (:func:`kalcal.stats.effects.cramer_rao_bound`'s renewed
states).

**The batch estimator** (``filter.kind=batch``): the maximum likelihood of procedure (b)
(:mod:`~.poses`: the 9 parameters and every pose's 2 tilts as free parameters, no prior), solved for a
whole block of realizations at once by Levenberg-Marquardt with each pose's tilts eliminated by their
2 x 2 Schur complement; its covariance is the information's 9-block of the inverse at the estimate. One
final estimate per realization: the final-time checks only (no sequence of innovations to be white). Its
residual for the NIS check is the fit's whitened residual in the left null space of its Jacobian (P - 9
components, chi-square with P - 9 degrees of freedom under the estimator's own model): it needs P >= 10.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from kalcal.models.settings import SettingError, require_nonnegative, require_positive, show
from kalcal.scenarios.imu_3axis.model import PARAM_NAMES, PARAM_UNITS, STANDARD_GRAVITY, h, pose_data
from kalcal.scenarios.imu_3axis.poses import MIN_POSES
from kalcal.scenarios.nonlinear.settings import COMPILED_MODES

#: the states of the filters: the 9 parameters, then the current pose's 2 tilts
STATE_NAMES = (*PARAM_NAMES, "tilt_1", "tilt_2")
STATE_UNITS = (*PARAM_UNITS, "rad", "rad")
PARAMS = tuple(range(9))
TILTS = (9, 10)
ESTIMATORS = ("ekf", "iekf", "ukf", "batch")
#: the default pose count of verify
DEFAULT_POSES = 12


@dataclass(frozen=True)
class TruthSection:
    """Section ``truth`` of ``verify``: the simulated poses, their noise, the tilts' spread and the prior.

    ``poses`` P (>= 9); ``layout``: ``spiral`` (P up directions on a golden spiral over the sphere) or a
    JSON file of P up vectors ``[[x, y, z], ...]`` in the sensor frame; ``noise`` (m/s^2): the standard
    deviation of a pose's mean reading per axis (0: ``sample_noise`` / sqrt(``rate`` ``pose_duration``),
    the mean of rate x duration white samples); ``tilt_spread`` (deg): each tangent tilt's standard
    deviation about the nominal pose; ``scale_std`` (1), ``misalignment_std`` (deg), ``bias_std`` (m/s^2):
    the prior standard deviations of the 9 parameters about scales 1, no misalignment and no bias.
    """

    poses: int = DEFAULT_POSES
    layout: str = "spiral"
    noise: float = 0.0
    sample_noise: float = 0.05
    rate: float = 100.0
    pose_duration: float = 2.0
    tilt_spread: float = 2.0
    scale_std: float = 0.01
    misalignment_std: float = 0.5
    bias_std: float = 0.1

    def __post_init__(self) -> None:
        require_positive("truth", sample_noise=self.sample_noise, rate=self.rate, pose_duration=self.pose_duration,
                         tilt_spread=self.tilt_spread, scale_std=self.scale_std, misalignment_std=self.misalignment_std,
                         bias_std=self.bias_std)
        require_nonnegative("truth", noise=self.noise)
        if isinstance(self.poses, bool) or int(self.poses) != self.poses:
            raise SettingError("truth.poses", "a whole number of poses", show(self.poses))
        if self.tilt_spread >= 20:
            raise SettingError("truth.tilt_spread", "a tilt below 20 deg (tangent coordinates)", show(self.tilt_spread))

    @property
    def mean_noise(self) -> float:
        """sigma, m/s^2: the standard deviation of a pose's mean reading per axis."""
        return float(self.noise) if self.noise > 0 else float(self.sample_noise / np.sqrt(self.rate * self.pose_duration))


@dataclass(frozen=True)
class EstimatorSection:
    """Section ``filter`` of ``verify``: the estimator (``ekf``, ``iekf``, ``ukf`` or ``batch``), the UKF's
    sigma points (``alpha``, ``beta``, ``kappa``), the IEKF's and the batch fit's ``max_iterations``, and
    ``compiled`` (``auto``, ``yes`` or ``no``): whether the EKF runs in the compiled kernel, as for a model
    written as code (:attr:`kalcal.scenarios.nonlinear.problem.NonlinearProblem.compiled_path`)."""

    kind: str = "ekf"
    alpha: float = 1.0
    beta: float = 2.0
    kappa: float = 0.0
    max_iterations: int = 20
    compiled: str = "auto"

    def __post_init__(self) -> None:
        if self.kind not in ESTIMATORS:
            raise SettingError("filter.kind", f"one of {', '.join(ESTIMATORS)}", show(self.kind))
        if self.compiled not in COMPILED_MODES:
            raise SettingError("filter.compiled", f"one of {', '.join(COMPILED_MODES)}", show(self.compiled))
        if isinstance(self.max_iterations, bool) or int(self.max_iterations) != self.max_iterations or self.max_iterations < 1:
            raise SettingError("filter.max_iterations", "a positive integer", show(self.max_iterations))


def spiral(count: int) -> np.ndarray:
    """``count`` unit vectors (count, 3) on a golden spiral: near-even cover of the sphere for any count."""
    i = np.arange(count) + 0.5
    z = 1.0 - 2.0 * i / count
    phi = i * np.pi * (3.0 - np.sqrt(5.0))
    r = np.sqrt(1.0 - z * z)
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


def nominal_poses(truth: TruthSection) -> np.ndarray:
    """The nominal up directions (P, 3) of the layout; refuses (one line) fewer than 9 poses or a bad file."""
    if truth.layout == "spiral":
        count = int(truth.poses)
        ups = spiral(max(count, 0))
    else:
        path = Path(truth.layout)
        try:
            ups = np.asarray(json.loads(path.read_text()), dtype=float)
        except (OSError, ValueError, TypeError) as exc:
            raise SettingError("truth.layout", "'spiral' or a JSON file of up vectors [[x, y, z], ...]", f"{truth.layout!r} ({exc})") from None
        if ups.ndim != 2 or ups.shape[1] != 3 or not np.all(np.isfinite(ups)) or np.any(np.linalg.norm(ups, axis=1) == 0):
            raise SettingError("truth.layout", "a JSON list of nonzero up vectors [[x, y, z], ...]", f"{truth.layout!r} of shape {ups.shape}")
        count = ups.shape[0]
        if truth.poses not in (count, DEFAULT_POSES):
            raise SettingError("truth.poses", f"{count}, the poses of {truth.layout}", show(truth.poses))
    if count < MIN_POSES:
        raise SettingError("truth.poses", f"at least {MIN_POSES} poses (3 equations each for 9 parameters and 2 tilts per pose)", show(count))
    return ups / np.linalg.norm(ups, axis=1, keepdims=True)


def prior(truth: TruthSection) -> tuple[np.ndarray, np.ndarray]:
    """The 11 states' prior mean and covariance: the nominal parameters with their stated spread, and a
    pose's tilts at the nominal pose with the stated tilt spread (rad)."""
    x0 = np.r_[np.ones(3), np.zeros(8)]
    std = np.r_[np.full(3, truth.scale_std), np.full(3, np.radians(truth.misalignment_std)), np.full(3, truth.bias_std),
                np.full(2, np.radians(truth.tilt_spread))]
    return x0, np.diag(std**2)


def _renew(x, u, dt):
    """f: the parameters kept, the tilts set to the next pose's prior mean (0: the nominal pose)."""
    return x * np.r_[np.ones(9), 0.0, 0.0]


@lru_cache(maxsize=8)
def pose_model(truth: TruthSection, gravity: float = STANDARD_GRAVITY):
    """The 11-state :class:`~kalcal.core.nonlinear.NonlinearModel` of the static poses (the module's
    docstring) and the poses' data (P, 9): truth and filters alike (one per settings, its Jacobians derived once)."""
    from kalcal.core.nonlinear import NonlinearModel

    ups = nominal_poses(truth)
    x0, p0 = prior(truth)
    q = np.zeros((11, 11))
    q[9:, 9:] = p0[9:, 9:]
    sigma = truth.mean_noise
    model = NonlinearModel(
        f=_renew, h=lambda x, data: h(x, data, gravity), q=q, r=sigma**2 * np.eye(3), x0=x0, p0=p0, dt=1.0,
        state_names=STATE_NAMES, state_units=STATE_UNITS, measurement_names=("reading_x", "reading_y", "reading_z"),
        measurement_units=("m/s^2",) * 3, data_dim=9,
    )
    return model, pose_data(ups)


def check_layout(truth: TruthSection, gravity: float, max_condition: float) -> float:
    """The condition number of the 9 parameters' information at the nominal poses (procedure (b)'s
    :func:`~.poses.condition`); refuses, in one line, a layout whose information is ill-conditioned."""
    from kalcal.scenarios.imu_3axis.poses import _Problem, condition, parameter_information

    model, data = pose_model(truth, gravity)
    means = h(np.tile(model.x0, (data.shape[0], 1)), data, gravity)
    cov = np.broadcast_to(model.r, (data.shape[0], 3, 3))
    problem = _Problem(means, cov, gravity)
    start = np.r_[model.x0[:9], np.zeros(2 * data.shape[0])]
    cond = condition(parameter_information(problem.jacobian(start)), gravity)
    if not np.isfinite(cond) or cond > max_condition:
        raise SettingError("truth.layout", f"poses that determine the 9 parameters (information condition number <= {max_condition:.3g})",
                           f"{truth.layout!r}: condition number {cond:.3g}")
    return cond


# -- the batch maximum likelihood, a block of realizations at once ----------------------------------------


def batch_ml(model, data: np.ndarray, z: np.ndarray, max_iterations: int = 50, tol: float = 1e-12):
    """Procedure (b)'s maximum likelihood for n realizations at once (the module's docstring).

    Parameters
    ----------
    model : NonlinearModel
        The 11-state pose model (its h, Jacobian, R and the nominal parameters x0[:9] as the start).
    data : ndarray, shape (P, 9)
        The poses' nominal up directions and tangent bases (the tilts' origin).
    z : ndarray, shape (n, P, 3)
        The poses' mean readings, m/s^2.
    max_iterations : int
        Levenberg-Marquardt steps at most (each realization stops when its relative cost change is below ``tol``).

    Returns
    -------
    theta : ndarray (n, 9); cov : ndarray (n, 9, 9), the information's; residual : ndarray (n, P - 9), the
    whitened residual in the left null space of the Jacobian; converged : ndarray (n,) bool
    """
    n, count, _ = z.shape
    from scipy.linalg import solve_triangular

    white = solve_triangular(np.linalg.cholesky(model.r), np.eye(3), lower=True)  # L^-1 of R = L L^T, 3 x 3 once
    flat_data = np.broadcast_to(data, (n, count, 9)).reshape(n * count, 9)
    theta = np.tile(model.x0[:9], (n, 1))
    tilts = np.zeros((n, count, 2))

    def evaluate(theta, tilts):
        x = np.concatenate([np.broadcast_to(theta[:, None], (n, count, 9)), tilts], axis=-1).reshape(n * count, 11)
        r = (z.reshape(n * count, 3) - model.measure(x, flat_data)) @ white.T
        return r.reshape(n, count, 3), x

    r, x = evaluate(theta, tilts)
    cost = np.einsum("npa,npa->n", r, r)
    lam = np.full(n, 1e-3)
    active = np.ones(n, dtype=bool)
    eye9, eye2 = np.eye(9), np.eye(2)
    for _ in range(int(max_iterations)):
        if not active.any():
            break
        jac = (white @ model.measurement_jacobian(x, flat_data)).reshape(n, count, 3, 11)
        jt, jd = jac[..., :9], jac[..., 9:]
        a = np.einsum("npai,npaj->nij", jt, jt)
        c = np.einsum("npai,npaj->npij", jt, jd)
        d = np.einsum("npai,npaj->npij", jd, jd)
        gt = np.einsum("npai,npa->ni", jt, r)
        gd = np.einsum("npai,npa->npi", jd, r)
        # Levenberg-Marquardt: the normal equations damped by lam times their diagonal (scale-free)
        a_d = a + lam[:, None, None] * np.diagonal(a, axis1=1, axis2=2)[..., None] * eye9
        d_d = d + lam[:, None, None, None] * np.diagonal(d, axis1=2, axis2=3)[..., None] * eye2
        d_c = np.linalg.solve(d_d, np.swapaxes(c, -1, -2))  # D^-1 C^T per pose, (n, P, 2, 9)
        d_g = np.linalg.solve(d_d, gd[..., None])[..., 0]
        schur = a_d - np.einsum("npij,npjk->nik", c, d_c)
        step_t = np.linalg.solve(schur, (gt - np.einsum("npij,npj->ni", c, d_g))[..., None])[..., 0]
        step_d = d_g - np.einsum("npij,nj->npi", d_c, step_t)
        new_theta = np.where(active[:, None], theta + step_t, theta)
        new_tilts = np.where(active[:, None, None], tilts + step_d, tilts)
        new_r, new_x = evaluate(new_theta, new_tilts)
        new_cost = np.einsum("npa,npa->n", new_r, new_r)
        better = active & (new_cost <= cost)
        done = better & (cost - new_cost <= tol * np.maximum(cost, 1e-300))
        theta = np.where(better[:, None], new_theta, theta)
        tilts = np.where(better[:, None, None], new_tilts, tilts)
        r = np.where(better[:, None, None], new_r, r)
        x = np.where(np.repeat(better, count)[:, None], new_x, x)
        cost = np.where(better, new_cost, cost)
        lam = np.where(better, lam / 10.0, lam * 10.0)
        active &= ~done
    converged = ~active
    jac = (white @ model.measurement_jacobian(x, flat_data)).reshape(n, count, 3, 11)
    jt, jd = jac[..., :9], jac[..., 9:]
    a = np.einsum("npai,npaj->nij", jt, jt)
    c = np.einsum("npai,npaj->npij", jt, jd)
    d = np.einsum("npai,npaj->npij", jd, jd)
    info = a - np.einsum("npij,npjk->nik", c, np.linalg.solve(d, np.swapaxes(c, -1, -2)))
    chol = np.linalg.cholesky(0.5 * (info + np.swapaxes(info, -1, -2)))
    inv_chol = np.linalg.solve(chol, np.broadcast_to(eye9, chol.shape))
    cov = np.swapaxes(inv_chol, -1, -2) @ inv_chol  # (L L^T)^-1 from the triangle's solve
    # the residual's components in the left null space of the full Jacobian (3P rows, 9 + 2P columns)
    full = np.zeros((n, 3 * count, 9 + 2 * count))
    full[:, :, :9] = jt.reshape(n, 3 * count, 9)
    for i in range(count):
        full[:, 3 * i:3 * i + 3, 9 + 2 * i:11 + 2 * i] = jd[:, i]
    basis, _ = np.linalg.qr(full, mode="complete")
    residual = np.einsum("nab,na->nb", basis[:, :, 9 + 2 * count:], r.reshape(n, 3 * count))
    return theta, cov, residual, converged


def batch_estimator(model, data: np.ndarray, max_iterations: int):
    """The batch ML as the nonlinear problem's :class:`~kalcal.scenarios.nonlinear.problem.BatchEstimator`."""
    from kalcal.scenarios.nonlinear.problem import BatchEstimator

    dof = data.shape[0] - MIN_POSES
    tally: list = []  # (unconverged, realizations) per block: list.append is atomic across the threads

    def estimate(z):
        # filter.max_iterations as set: a realization whose fit has not converged within it is counted
        # (summary.json's batch_convergence), its estimate the last accepted iterate
        theta, cov, residual, converged = batch_ml(model, data, z, max_iterations=int(max_iterations))
        tally.append((int(np.count_nonzero(~converged)), int(converged.size)))
        return theta, cov, residual, np.broadcast_to(np.eye(dof), (z.shape[0], dof, dof))

    names = tuple(f"fit_residual_{i + 1}" for i in range(dof))
    return BatchEstimator(estimate, names, ("1",) * dof, tally)
