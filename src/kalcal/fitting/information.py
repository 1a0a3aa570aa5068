"""The observed information of a fit: the Hessian of -log L, the test that a search is done, and flat directions.

f = -log L over u (the parameters' log values, :mod:`kalcal.fitting.mle`). :func:`hessian` is the
observed information by central differences; :func:`stationary` says whether a search that L-BFGS-B did
not call converged is at the maximum to what matters (a Newton step's predicted gain of log L); and
:func:`ridges` finds the parameters on a direction the information does not see (two or more trading off).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from kalcal.fitting.local_search import evaluate_all, gradient

#: step of the central differences in u = log(value) for the Hessian
HESSIAN_STEP = 1e-2
#: a projected gradient of log L in u below this counts as the optimum (log L changes by < 1e-7 over 1e-3)
STATIONARY = 1e-4
#: a search also counts as converged where a Newton step over the interior parameters would raise log L by
#: less than this: far below the 0.5 per parameter that is statistically anything, far above the rounding
#: noise of log L (about 1e-8 on a log with the diffuse bias prior), which stops L-BFGS-B's line search
#: before the gradient falls below :data:`STATIONARY` where the curvature is large (hundreds per unit of u)
GAIN = 1e-3
#: a parameter whose component in a flat direction's unit vector is at least this in size takes part in it
RIDGE_SHARE = 0.1


def stationary(f, u: np.ndarray, low: np.ndarray, high: np.ndarray, interior: Sequence[int],
               hess: np.ndarray | None) -> bool:
    """Whether f is at its minimum within the bounds at u, to what matters (a line search that stops on
    rounding at the optimum is a converged search): the projected gradient of f is below
    :data:`STATIONARY` along each parameter outside ``interior``, and along the ``interior`` ones (where
    ``hess``, their Hessian of f, is positive definite) the Newton step's predicted decrease
    1/2 g^T H^-1 g is below :data:`GAIN` (or their gradient below :data:`STATIONARY`)."""
    if u.size == 0:
        return True
    grad = gradient(f, u, low, high)
    grad[(u <= low + 1e-9) & (grad > 0)] = 0.0
    grad[(u >= high - 1e-9) & (grad < 0)] = 0.0
    inner = list(interior) if hess is not None else []
    outer = np.ones(u.size, dtype=bool)
    outer[inner] = False
    if np.any(np.abs(grad[outer]) >= STATIONARY):
        return False
    g = grad[inner]
    return bool(np.max(np.abs(g), initial=0.0) < STATIONARY or 0.5 * g @ np.linalg.solve(hess, g) < GAIN)


def hessian(f: Callable[[np.ndarray], float], u: np.ndarray, index: Sequence[int]) -> np.ndarray:
    """The Hessian of f over the coordinates ``index`` at u, central differences of step HESSIAN_STEP;
    its evaluations run together (:func:`~kalcal.fitting.local_search.evaluate_all`)."""
    n, h = len(index), HESSIAN_STEP
    points, cells = [u], []  # the centre, then each cell's points: 2 on the diagonal, 4 corners off it
    for a, i in enumerate(index):
        for b, j in enumerate(index[: a + 1]):
            first = len(points)
            if i == j:
                up, down = u.copy(), u.copy()
                up[i] += h
                down[i] -= h
                points += [up, down]
            else:
                for si, sj in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
                    v = u.copy()
                    v[i] += si * h
                    v[j] += sj * h
                    points.append(v)
            cells.append((a, b, first, i == j))
    values = evaluate_all(f, points)
    center = values[0]
    hess = np.empty((n, n))
    for a, b, first, diagonal in cells:
        if diagonal:
            value = (values[first] - 2 * center + values[first + 1]) / h**2
        else:
            corners = values[first : first + 4]
            value = (corners[0] - corners[1] - corners[2] + corners[3]) / (4 * h * h)
        hess[a, b] = hess[b, a] = value
    return hess


def ridges(f, u_hat, low, high, interior, hess, drop) -> dict[int, list[int]]:
    """The ``interior`` parameters on a flat direction of log L = -f (two or more trading off, a ridge not
    along an axis): an eigenvector v of ``hess`` (the Hessian of f over ``interior``) whose eigenvalue
    lambda is near zero, |lambda| t^2 / 2 < ``drop`` with t the reach of the search box from u_hat along
    +-v (the farther one): by the quadratic model log L changes by less than ``drop`` along it over the
    range. Returns each such parameter with the others of its direction."""
    flagged: dict[int, list[int]] = {}
    eigenvalues, vectors = np.linalg.eigh(hess)
    for lam, v in zip(eigenvalues, vectors.T):
        d = np.zeros(u_hat.size)
        d[interior] = v
        with np.errstate(divide="ignore", invalid="ignore"):
            reach = [float(np.min(np.where(s * d > 0, (high - u_hat) / (s * d), np.where(s * d < 0, (low - u_hat) / (s * d), np.inf))))
                     for s in (1.0, -1.0)]
        if abs(lam) * max(reach) ** 2 / 2.0 < drop:
            members = [i for i, x in zip(interior, v) if abs(x) >= RIDGE_SHARE]
            for i in members:
                flagged[i] = sorted(set(flagged.get(i, [])) | {j for j in members if j != i})
    return flagged
