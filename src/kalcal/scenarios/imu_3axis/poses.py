"""Procedure (b), unknown poses: the 9 parameters by maximum likelihood, intervals from the information and a bootstrap.

The parameters are :data:`~.model.PARAM_NAMES`, estimated from the poses' means.

Only |f_i| = g is known of pose i, so the magnitude equations |M^-1 (ā_i - b)| = g carry the information.
Their Gaussian maximum likelihood is solved in its exact form: each pose's 2 tilt angles (tangent
coordinates around the normalized mean reading, :func:`~.model.h`) are nuisance parameters beside the 9, and
Levenberg-Marquardt (``scipy.optimize.least_squares``) minimizes sum_i |L_i^-1 (ā_i - h(theta, d_i))|^2, L_i
the Cholesky factor of the mean's covariance; minimizing over a pose's tilts leaves the Mahalanobis
distance of ā_i to the ellipsoid M {|f| = g} + b, whose first order is the weighted magnitude residual.
With N poses there are 3N equations and 9 + 2N unknowns: N >= 9 is needed (N - 9 degrees of freedom for
the fit's chi-square).

The information is J^T J of the whitened residuals; the parameters' covariance is the 9-block of its
inverse (the Cramér–Rao bound at the estimate). A layout that leaves a direction of the 9 unseen (poses in
one plane, or a small cap of the sphere) makes that block's information ill-conditioned: its condition
number, in dimensionless units (biases / g), above ``max_condition`` is refused.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from kalcal.errors import DataError
from kalcal.scenarios.imu_3axis.model import PARAM_NAMES, h, pose_data

#: fewest poses (3N equations for 9 + 2N unknowns)
MIN_POSES = 9


@lru_cache(maxsize=1)
def _jacobian():
    """d h / d [theta, d] (3, 11) as a numpy function of (x (11,), data (9,), g): sympy once, then compiled."""
    import sympy

    x = np.array(sympy.symbols("x0:11"), dtype=object)
    data = np.array(sympy.symbols("n0:9"), dtype=object)
    g = sympy.Symbol("g")
    out = h(x, data, g)
    matrix = sympy.Matrix(3, 1, list(out)).jacobian(list(x))
    return sympy.lambdify((list(x), list(data), g), matrix, "numpy")


def _whiteners(mean_cov: np.ndarray, names=None, source: str = "poses") -> np.ndarray:
    """L_i^-1 (N, 3, 3) of each mean's covariance (Cholesky; a solve against the identity of a triangle);
    a covariance that is not positive definite is refused (DataError naming the pose), not a traceback."""
    from scipy.linalg import solve_triangular

    out = np.empty_like(mean_cov)
    for i, cov in enumerate(mean_cov):
        try:
            chol = np.linalg.cholesky(cov)
        except np.linalg.LinAlgError:
            pose = names[i] if names is not None else f"number {i + 1}"
            raise DataError(f"{source}: pose {pose!r}: its mean's covariance is singular (variances "
                            f"{', '.join(f'{v:.3g}' for v in np.diag(cov))} (m/s^2)^2): an axis whose readings do not vary "
                            "carries no noise estimate; record a longer pose or a log with a finer resolution") from None
        out[i] = solve_triangular(chol, np.eye(3), lower=True)
    return out


class _Problem:
    def __init__(self, means, mean_cov, gravity, names=None, source="poses"):
        self.means, self.gravity = means, gravity
        self.data = pose_data(means)  # the tilts' origin: each pose's normalized mean reading
        self.white = _whiteners(mean_cov, names, source)
        self.n = means.shape[0]
        self.jac = _jacobian()

    def split(self, z):
        return z[:9], z[9:].reshape(self.n, 2)

    def x(self, z):
        theta, tilts = self.split(z)
        return np.hstack([np.tile(theta, (self.n, 1)), tilts])

    def residuals(self, z):
        predicted = h(self.x(z), self.data, self.gravity)
        return np.einsum("nij,nj->ni", self.white, self.means - predicted).ravel()

    def jacobian(self, z):
        x = self.x(z)
        J = np.zeros((3 * self.n, 9 + 2 * self.n))
        for i in range(self.n):
            Hi = -self.white[i] @ np.asarray(self.jac(x[i], self.data[i], self.gravity), dtype=float)
            J[3 * i: 3 * i + 3, :9] = Hi[:, :9]
            J[3 * i: 3 * i + 3, 9 + 2 * i: 11 + 2 * i] = Hi[:, 9:]
        return J


def parameter_information(J: np.ndarray) -> np.ndarray:
    """The 9 parameters' information with the tilts profiled out (the Schur complement of J^T J), (9, 9)."""
    info = J.T @ J
    a, c = info[:9, :9], info[:9, 9:]
    n = (info.shape[0] - 9) // 2
    schur = a.copy()
    for i in range(n):  # the tilts' block is block-diagonal: one 2x2 solve per pose
        block = slice(9 + 2 * i, 11 + 2 * i)
        schur -= c[:, 2 * i: 2 * i + 2] @ np.linalg.solve(info[block, block], c[:, 2 * i: 2 * i + 2].T)
    return schur


def condition(info: np.ndarray, gravity: float) -> float:
    """The condition number of the 9 parameters' information in dimensionless units (biases in g)."""
    scale = np.r_[np.ones(6), np.full(3, gravity)]
    return float(np.linalg.cond(info / np.outer(scale, scale)))


def initial(means: np.ndarray, gravity: float) -> np.ndarray:
    """The start: scales |ā| / g averaged, no misalignment, no bias, no tilt from the normalized readings."""
    scale = float(np.mean(np.linalg.norm(means, axis=1))) / gravity
    return np.r_[np.full(3, scale), np.zeros(6), np.zeros(2 * means.shape[0])]


@dataclass(frozen=True)
class PoseCalibration:
    """Procedure (b)'s answer: ``theta`` (9,) in :data:`PARAM_NAMES`' units, ``covariance`` (9, 9) from the
    information, the poses' ``tilts`` (N, 2) rad, the ``chi2`` of the fit with ``dof`` = N - 9 and its
    ``p_value``, the information's ``condition``, the ``residuals`` (N, 3) m/s^2, and the bootstrap's
    replicates (B, 9) (empty when B = 0)."""

    theta: np.ndarray
    covariance: np.ndarray
    tilts: np.ndarray
    chi2: float
    dof: int
    p_value: float
    condition: float
    residuals: np.ndarray
    means: np.ndarray
    mean_cov: np.ndarray
    bootstrap: np.ndarray

    def std(self) -> np.ndarray:
        return np.sqrt(np.diag(self.covariance))


def _solve(problem: _Problem, start: np.ndarray):
    from scipy.optimize import least_squares

    return least_squares(problem.residuals, start, jac=problem.jacobian, method="lm", xtol=1e-12, ftol=1e-12, gtol=1e-12)


def fit_poses(means: np.ndarray, mean_cov: np.ndarray, gravity: float, *, max_condition: float = 1e8,
              bootstrap: int = 0, seed: int = 0, source: str = "poses", names=None) -> PoseCalibration:
    """Procedure (b) from the poses' means (N, 3), m/s^2, and their covariances (N, 3, 3); refuses (DataError,
    one line naming ``source``) fewer than 9 poses or a layout whose information's condition number exceeds
    ``max_condition``, or a pose (named by ``names``, default its number) whose mean's covariance is not
    positive definite. ``bootstrap`` replicates (B; 0: none) simulate the means from the fit (the fitted
    poses and the means' covariances) and refit, with the generator seeded by ``seed``."""
    from kalcal.stats.distributions import chi2_sf

    means, mean_cov = np.asarray(means, dtype=float), np.asarray(mean_cov, dtype=float)
    n = means.shape[0]
    if n < MIN_POSES:
        raise DataError(f"{source}: {n} poses; procedure (b) needs at least {MIN_POSES} (3 equations each for 9 parameters and 2 tilts per pose)")
    problem = _Problem(means, mean_cov, gravity, names, source)
    start = initial(means, gravity)
    cond = condition(parameter_information(problem.jacobian(start)), gravity)
    if not np.isfinite(cond) or cond > max_condition:
        raise DataError(f"{source}: the {n} poses leave the 9 parameters ill-determined: the information's condition "
                        f"number is {cond:.3g} > {max_condition:.3g} (scenario.max_condition): poses near the six faces "
                        "alone, or in one region of the sphere, do not separate the scales, misalignments and biases; "
                        "add poses in general orientations, between the axes")
    solution = _solve(problem, start)
    if solution.status <= 0 or not np.all(np.isfinite(solution.x)):
        # 0: the evaluations' limit reached; -1: improper input: no maximum likelihood to give intervals about
        raise DataError(f"{source}: the fit of the {n} poses did not converge (least squares status {solution.status}: "
                        f"{solution.message}): check the poses are static and in m/s^2")
    theta, tilts = problem.split(solution.x)
    info = parameter_information(problem.jacobian(solution.x))
    from scipy.linalg import LinAlgError, cho_factor, cho_solve

    try:
        covariance = cho_solve(cho_factor(info), np.eye(9))
    except LinAlgError:
        raise DataError(f"{source}: the 9 parameters' information at the fit is singular (condition number "
                        f"{condition(info, gravity):.3g}): the poses leave a direction of them undetermined; add poses in "
                        "general orientations") from None

    chi2 = float(2 * solution.cost)
    dof = n - 9
    p_value = float(chi2_sf(chi2, dof)) if dof > 0 else float("nan")
    residuals = means - h(problem.x(solution.x), problem.data, gravity)
    replicates = np.empty((0, 9))
    if bootstrap > 0:
        rng = np.random.default_rng(seed)
        fitted = h(problem.x(solution.x), problem.data, gravity)
        chol = np.linalg.cholesky(mean_cov)
        replicates = np.empty((bootstrap, 9))
        for r in range(bootstrap):
            simulated = fitted + np.einsum("nij,nj->ni", chol, rng.standard_normal((n, 3)))
            again = _Problem(simulated, mean_cov, gravity)
            replicates[r] = _solve(again, np.r_[theta, np.zeros(2 * n)]).x[:9]
    return PoseCalibration(theta, covariance, tilts, chi2, dof, p_value, cond, residuals, means, mean_cov, replicates)


assert len(PARAM_NAMES) == 9
