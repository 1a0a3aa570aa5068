"""The local searches of a fit: L-BFGS-B within bounds with central-difference gradients, and the profile likelihood.

Both minimize f = -log L over u (the parameters' log values, or a linear parameter's scaled value,
:mod:`kalcal.fitting.mle`). A profile point re-maximizes log L over the other parameters with one
parameter held; each such search starts from the optimum of the nearest point already profiled along that
parameter (a warm start: neighbouring points' optima differ little) and stops when an iteration changes
log L by less than :data:`PROFILE_TOL`: an inner optimum off by du changes the profile by second order in
du only, far below what moves an interval's end.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from scipy import optimize

#: step of the central differences in u for the gradient
GRADIENT_STEP = 1e-4
#: a profile point's search stops when an iteration changes log L by less than this (log L units)
PROFILE_TOL = 1e-4


def gradient(f: Callable[[np.ndarray], float], u: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """The gradient of f at u by central differences of :data:`GRADIENT_STEP`, one-sided at a bound, (n,).

    Its 2n evaluations run on the CPUs this process may use (:func:`evaluate_all`): the same values as
    one after another, since each evaluation depends on its point alone."""
    ups, downs = [], []
    for i in range(u.size):
        up, down = u.copy(), u.copy()
        up[i], down[i] = min(u[i] + GRADIENT_STEP, high[i]), max(u[i] - GRADIENT_STEP, low[i])
        ups.append(up)
        downs.append(down)
    values = evaluate_all(f, ups + downs)
    grad = np.empty_like(u)
    for i in range(u.size):
        grad[i] = (values[i] - values[u.size + i]) / (ups[i][i] - downs[i][i])
    return grad


def evaluate_all(f: Callable[[np.ndarray], float], points: Sequence[np.ndarray], workers: int | None = None) -> list[float]:
    """``[f(p) for p in points]``, on ``workers`` threads (default: the CPUs this process may use).

    A log's likelihood spends most of an evaluation in the compiled filter, which releases the GIL
    (filters/sequential.py), so that two threads take about 0.6x the time of one; ``f`` must not depend
    on the order of its calls (a fit's objective counts its calls under a lock, :mod:`kalcal.fitting.mle`).
    """
    if workers is None:
        workers = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    workers = max(1, min(workers, len(points)))
    if workers == 1:
        return [f(point) for point in points]
    with ThreadPoolExecutor(workers, thread_name_prefix="kalcal-gradient") as pool:
        return list(pool.map(f, points))


def minimize(f, u0: np.ndarray, low: np.ndarray, high: np.ndarray, ftol: float = 1e-14):
    """L-BFGS-B from u0 within [low, high] (scipy's ``OptimizeResult``); ``ftol`` is its relative change
    of f that stops it."""
    if u0.size == 0:
        return optimize.OptimizeResult(x=u0, fun=f(u0), success=True, message="nothing free")
    return optimize.minimize(
        f, u0, jac=lambda u: gradient(f, u, low, high), method="L-BFGS-B", bounds=list(zip(low, high)),
        options={"maxiter": 500, "ftol": ftol, "gtol": 1e-6},
    )


class Profile:
    """The profile of log L = -f along each parameter, the others re-maximized from warm starts.

    Each point is computed once (a point asked again, such as a range end that was tested for flatness, is
    looked up), and at the maximum the profile is log L itself. A crossing of a level is bracketed
    outward from the maximum first, from the slice's own crossing (the profile falls no faster than the
    slice), doubling the step, and then found by brentq within that bracket.

    Parameters
    ----------
    f : callable
        f(u) = -log L, u of shape (n,).
    u_hat : ndarray, (n,)
        The maximum; the profile's first point along each parameter, and where it is log L itself.
    low, high : ndarray, (n,)
        The search bounds of u.
    loglik : float
        log L at ``u_hat``: its scale sets the searches' relative tolerance (:data:`PROFILE_TOL` absolute).
    """

    def __init__(self, f, u_hat: np.ndarray, low: np.ndarray, high: np.ndarray, loglik: float):
        self.f, self.u_hat, self.low, self.high, self.loglik = f, u_hat, low, high, float(loglik)
        self.ftol = PROFILE_TOL / max(abs(loglik), 1.0)
        self.points: dict[int, list[tuple[float, np.ndarray]]] = {}
        self.known: dict[tuple[int, float], float] = {}
        self.searches = 0
        self.curvatures: dict[int, float] = {}

    def __call__(self, i: int, value: float) -> float:
        """log L with u_i = ``value``, the others re-maximized."""
        value = float(value)
        if value == float(self.u_hat[i]):
            return self.loglik
        if (i, value) in self.known:
            return self.known[i, value]
        u = self.u_hat.copy()
        u[i] = value
        others = [j for j in range(u.size) if j != i]
        if not others:
            return -float(self.f(u))
        done = self.points.setdefault(i, [(float(self.u_hat[i]), self.u_hat[others])])
        start = min(done, key=lambda point: abs(point[0] - value))[1]

        def g(w):
            v = u.copy()
            v[others] = w
            return self.f(v)

        result = minimize(g, start, self.low[others], self.high[others], ftol=self.ftol)
        self.searches += 1
        done.append((value, np.asarray(result.x, dtype=float)))
        self.known[i, value] = -float(result.fun)
        return self.known[i, value]

    def crossing(self, i: int, end: float, level: float) -> float:
        """The u_i between the maximum and ``end`` where the profile falls to ``level`` (brentq, 1e-4 in u);
        the profile at ``end`` is below ``level``."""
        start, sign = float(self.u_hat[i]), float(np.sign(end - self.u_hat[i]))
        curvature = self._curvature(i)
        step = np.sqrt(2.0 * (self.loglik - level) / curvature) if curvature > 0 else abs(end - start) / 8.0
        inner = start
        while True:
            outer = start + sign * step
            if sign * (outer - end) >= 0:
                outer = end
                break
            if self(i, outer) < level:
                break
            inner, step = outer, 2.0 * step
        return optimize.brentq(lambda v: self(i, v) - level, inner, outer, xtol=1e-4)

    def _curvature(self, i: int) -> float:
        """The slice's second difference of -log L along u_i at the maximum (step 1e-2), once per i."""
        if i not in self.curvatures:
            h = 1e-2
            up, down = self.u_hat.copy(), self.u_hat.copy()
            up[i] += h
            down[i] -= h
            self.curvatures[i] = (self.f(up) - 2.0 * (-self.loglik) + self.f(down)) / h**2
        return self.curvatures[i]
