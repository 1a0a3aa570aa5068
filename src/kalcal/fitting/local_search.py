"""The local searches of a fit: L-BFGS-B within bounds with central-difference gradients, and the profile likelihood.

A gradient's evaluations run together on threads where they are long enough (:func:`evaluate_all`).

Both minimize f = -log L over u (the parameters' log values, or a linear parameter's scaled value,
:mod:`kalcal.fitting.mle`). A profile point re-maximizes log L over the other parameters with one
parameter held; each such search starts from the optimum of the nearest point already profiled along that
parameter (a warm start: neighbouring points' optima differ little) and stops when an iteration changes
log L by less than :data:`PROFILE_TOL`: an inner optimum off by du changes the profile by second order in
du only, far below what moves an interval's end.
"""

from __future__ import annotations

import contextvars
import os
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor, wait

import numpy as np
from scipy import optimize

from kalcal.cpus import usable_cpus

#: step of the central differences in u for the gradient
GRADIENT_STEP = 1e-4
#: a profile point's search stops when an iteration changes log L by less than this (log L units)
PROFILE_TOL = 1e-4
#: an evaluation shorter than this (s) is not worth a thread: handing it over and sharing the GIL cost
#: more (a log of a few hundred measurements, a two-state model); one of a long log's filter runs takes ~10 ms
THREAD_MIN_S = 2e-3

#: the evaluation threads' names start with this
THREAD_PREFIX = "kalcal-evaluate"

#: the evaluation threads, by count, made once per process and kept (a pool per call cost 1.5-3.5 ms)
_POOLS: dict[int, ThreadPoolExecutor] = {}
_POOLS_LOCK = threading.Lock()
#: set in an evaluation thread: an evaluate_all called from inside one runs there, one after another
_IN_POOL = threading.local()


def _forget_pools() -> None:
    """In a forked child: the parent's threads are not there, so neither are its pools."""
    global _POOLS_LOCK
    _POOLS.clear()
    _POOLS_LOCK = threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_pools)


def gradient(f: Callable[[np.ndarray], float], u: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """The gradient of f at u by central differences of :data:`GRADIENT_STEP`, one-sided at a bound, (n,).

    Its 2n evaluations go to :func:`evaluate_all`: the same values as one after another."""
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


def evaluate_all(f: Callable[[np.ndarray], float], points: Sequence, workers: int | None = None) -> list[float]:
    """``[f(p) for p in points]``, the later points on threads when the first took long enough.

    The first point is evaluated here; if it took at least :data:`THREAD_MIN_S`, the others run on
    ``workers`` threads kept for the process, each in a copy of this thread's context (``np.errstate``
    and other context variables reach it), and this thread waits. A long log's likelihood spends most
    of an evaluation in the compiled filter, which releases the GIL (filters/sequential.py), so the
    threads overlap. ``f`` must be safe to call from several threads at once and give each point's value
    whatever else runs: every likelihood of kalcal's fits is (they read their log and write only what
    they allocate).

    Parameters
    ----------
    f : callable
        f(point) -> float.
    points : sequence
        The points, in the order of the values returned.
    workers : int, optional
        Threads (default: the CPUs this process may use, :func:`kalcal.cpus.usable_cpus`). 1, two points
        or fewer, or a call from inside an evaluation thread evaluate every point here, one after another.

    Returns
    -------
    list of float
        f at each point, in ``points``' order. An error of f is raised here (the point first in order
        that failed among those started); an interrupt waits for the running evaluations.
    """
    points = list(points)
    if not points:
        return []
    started = time.perf_counter()
    values = [f(points[0])]
    alone = len(points) <= 2 or getattr(_IN_POOL, "active", False) or time.perf_counter() - started < THREAD_MIN_S
    workers = 1 if alone else usable_cpus() if workers is None else int(workers)  # the CPUs asked only past the gate
    if workers <= 1:
        return values + [f(point) for point in points[1:]]
    pool = _pool(workers)
    futures = [pool.submit(contextvars.copy_context().run, _in_pool, f, point) for point in points[1:]]
    try:
        return values + [future.result() for future in futures]
    except BaseException:
        for future in futures:
            future.cancel()
        wait(futures)  # the running evaluations finish before the error goes on
        raise


def _pool(workers: int) -> ThreadPoolExecutor:
    with _POOLS_LOCK:
        if workers not in _POOLS:
            _POOLS[workers] = ThreadPoolExecutor(workers, thread_name_prefix=THREAD_PREFIX)
        return _POOLS[workers]


def _in_pool(f: Callable, point) -> float:
    _IN_POOL.active = True
    return f(point)


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
