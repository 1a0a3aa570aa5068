"""Maximize a log-likelihood over settings on a log or linear scale, with 95% intervals and flatness flags.

The search runs over u = log(value) within bounds (a parameter with ``scale="linear"``, such as a time
offset that may be negative: u = value) (L-BFGS-B, central-difference gradients), from the given
starts. Then, with ``drop`` = chi2.ppf(confidence, 1) / 2 (1.92 at 95%), each parameter is judged
along its own direction: the slice of log L through the optimum (the others held there) by default, or
its profile (the others re-maximized, :class:`kalcal.fitting.local_search.Profile`) with ``profile=True``:

* **unidentified** (flat): log L at both ends of the search range is within ``drop`` of the maximum,
  so the log cannot tell any value in the range from the estimate;
* **trading off** (a ridge, :func:`kalcal.fitting.information.ridges`): unidentified too, value None,
  ``trades_off`` naming the others; only their combination is identified, and the fitted point on the
  ridge is what a fitted filter runs with (:func:`kalcal.fitting.result.fitted_point`);
* **at the lower bound** ("consistent with 0", log scale): only the lower end is within ``drop``; the
  interval is [0, upper limit], the upper limit where log L has fallen by ``drop`` (linear scale: no
  lower limit within the range, None);
* otherwise the interval is u_hat +- z se mapped back (exp on the log scale), se from the observed
  information (the inverse of the negated Hessian of log L in u over the interior, identified
  parameters, by central differences), or the two points where the profile has fallen by ``drop``
  (Wilks); where that Hessian is not positive definite, the profile's points too (the parameter's note
  says so), judged anew at the range's ends: along a ridge the profile may stay within ``drop`` where
  the slice fell (no limit on that side; "consistent with 0" on a log scale's lower side; unidentified
  where it falls at neither end). A side where log L never falls
  by ``drop`` within the range has no limit (None).

``converged`` is L-BFGS-B's own verdict, or, where it stopped otherwise (its line search stops on the
rounding noise of log L near the maximum), that the estimate is the maximum to what matters
(:func:`kalcal.fitting.information.stationary`: a Newton step's predicted gain of log L over the
observed information's parameters, and the projected gradient along the others). When a point evaluated
for the curves beats the maximum found (the search stopped at a local maximum), the search restarts
from it (``restarts`` times at most); if a point still beats the reported maximum, ``converged`` is
False whatever the optimizer said, and the message names the point.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy import optimize

from kalcal.fitting.information import ridges, stationary
from kalcal.fitting.information import hessian as _hessian
from kalcal.fitting.local_search import Profile, evaluate_all, minimize
from kalcal.fitting.result import FitParameter
from kalcal.stats.distributions import chi2_ppf, normal_isf  # scipy.stats's values, without its import

#: a linear parameter's u counts its value in this many parts of its range
LINEAR_STEPS = 1000.0
#: a curve point whose log L exceeds the maximum found by more than this marks the search not converged
BEATEN = 1e-4
#: a bootstrap refit's relative change of -log L that stops its search (:func:`point_estimate`)
REFIT_FTOL = 1e-10
#: what an evaluation that fails (a setting the model refuses, a singular S_k) counts as: far below any fit
FAILED = -1e300


@dataclass(frozen=True)
class Free:
    """A free parameter: its name, unit, start and search range [lower, upper] (0 < lower < upper on the
    log scale; any lower <= start <= upper with ``scale="linear"``).

    ``bounded``: a linear-scale range whose ends are the parameter space's own bounds (an AR(1) coefficient's
    [-1, 1]), not only where the search stops; a log-scale range's lower end always stands for the bound 0
    (:func:`kalcal.fitting.bootstrap.boundary_ends`)."""

    name: str
    start: float
    lower: float
    upper: float
    unit: str = ""
    scale: str = "log"
    bounded: bool = False

    def __post_init__(self) -> None:
        if self.scale not in ("log", "linear"):
            raise ValueError(f"{self.name}: scale must be 'log' or 'linear', got {self.scale!r}")
        if not (0 < self.lower or self.scale == "linear") or not self.lower <= self.start <= self.upper:
            raise ValueError(f"{self.name}: expected 0 < lower <= start <= upper, got {self.lower!r}, {self.start!r}, {self.upper!r}")


@dataclass(frozen=True)
class MleFit:
    """The maximum and what each parameter's direction says about it."""

    values: dict[str, float]  #: the estimate of every free parameter, even the flat ones
    loglik: float
    converged: bool
    parameters: dict[str, FitParameter]
    curves: dict[str, dict[str, list[float]]]
    interval_method: str
    evaluations: int
    message: str = ""
    notes: tuple[str, ...] = ()  #: what the user must know about the intervals

    @property
    def aic(self) -> float:
        """2 k - 2 log L."""
        return 2.0 * len(self.values) - 2.0 * self.loglik


class _Objective:
    """-log L in u, counting evaluations; a failing evaluation is :data:`FAILED`."""

    def __init__(self, loglik: Callable[[Mapping[str, float]], float], names: Sequence[str], linear: np.ndarray,
                 units: np.ndarray):
        self.loglik, self.names, self.count, self.linear, self.units = loglik, list(names), 0, linear, units
        self._counting = threading.Lock()  # evaluations may run on threads (local_search.evaluate_all)

    def values(self, u: np.ndarray) -> np.ndarray:
        """The parameters' values at u."""
        return np.where(self.linear, u * self.units, np.exp(np.where(self.linear, 0.0, u)))

    def u_of(self, x: np.ndarray) -> np.ndarray:
        """u at the values x."""
        return np.where(self.linear, x / self.units, np.log(np.where(self.linear, 1.0, x)))

    def loglik_at(self, u: np.ndarray) -> float:
        with self._counting:
            self.count += 1
        return guarded(self.loglik, dict(zip(self.names, self.values(u).tolist())))


def drop_of(confidence: float) -> float:
    """The fall of log L from its maximum that bounds a ``confidence`` interval: chi2.ppf(confidence, 1) / 2
    (Wilks; 1.92 at 0.95)."""
    return float(chi2_ppf(confidence, 1)) / 2.0


def guarded(loglik: Callable[[Mapping[str, float]], float], values: Mapping[str, float]) -> float:
    """``loglik(values)``, or :data:`FAILED` where it raises a numerical error or is not finite."""
    try:
        value = float(loglik(values))
    except (ValueError, ArithmeticError, np.linalg.LinAlgError):
        return FAILED
    return value if np.isfinite(value) else FAILED


def maximize(
    loglik: Callable[[Mapping[str, float]], float],
    free: Sequence[Free],
    *,
    profile: bool = False,
    confidence: float = 0.95,
    curve_points: int = 15,
    restarts: int = 2,
) -> MleFit:
    """Maximize ``loglik`` over the ``free`` parameters and judge each one (see the module's docstring).

    Parameters
    ----------
    loglik : callable
        ``loglik({name: value})`` -> log L (a float; it may raise ValueError for a refused setting). A
        gradient's, a Hessian's and a slice's evaluations may run on several threads at once
        (:func:`~kalcal.fitting.local_search.evaluate_all`): it must be safe to call concurrently.
    free : sequence of Free
    profile : bool
        Intervals and flatness from the profile likelihood instead of the observed information and slice.
    confidence : float
        Of the intervals, in (0, 1).
    curve_points : int
        Points of each parameter's curve for the figure.
    restarts : int
        Searches restarted from a curve point that beats the maximum found, before the fit is reported
        not converged.
    """
    names = [p.name for p in free]
    linear = np.array([p.scale == "linear" for p in free], dtype=bool)
    # a linear parameter's u is in units of 1/1000 of its range, so that the steps and tolerances in u
    # mean for it about what they mean for log(value)
    units = np.array([(p.upper - p.lower) / LINEAR_STEPS if p.scale == "linear" else 1.0 for p in free], dtype=float)
    objective = _Objective(loglik, names, linear, units)
    to_u = objective.u_of
    low = to_u(np.array([p.lower for p in free], dtype=float))
    high = to_u(np.array([p.upper for p in free], dtype=float))
    u0 = np.clip(to_u(np.array([p.start for p in free], dtype=float)), low, high)
    f = lambda u: -objective.loglik_at(u)  # noqa: E731
    result = minimize(f, u0, low, high)
    u_hat, best = np.asarray(result.x, dtype=float), -float(result.fun)
    drop = drop_of(confidence)
    z = float(normal_isf((1.0 - confidence) / 2.0))

    profiled = Profile(f, u_hat, low, high, best)

    def along(i: int, value: float) -> float:
        """log L with u_i = value: the slice, or with ``profile`` the others re-maximized."""
        if profile:
            return profiled(i, value)
        u = u_hat.copy()
        u[i] = value
        return objective.loglik_at(u)

    def crossing(i: int, end: float) -> float:
        """The u between u_hat_i and ``end`` where log L has fallen by ``drop``."""
        if profile:
            return profiled.crossing(i, end, best - drop)
        return optimize.brentq(lambda v: along(i, v) - (best - drop), u_hat[i], end, xtol=1e-4)

    ends = {}
    for i in range(len(free)):
        at_low = along(i, low[i]) if u_hat[i] > low[i] + 1e-9 else best
        at_high = along(i, high[i]) if u_hat[i] < high[i] - 1e-9 else best
        ends[i] = (best - at_low >= drop, best - at_high >= drop)
    interior = [i for i, (falls_low, falls_high) in ends.items() if falls_low and falls_high]
    se, hess, ridge = {}, None, {}
    if interior and (not profile or not result.success):
        full = _hessian(f, u_hat, interior)
        if not profile:  # a profile's ends already see a ridge: the others re-maximized follow it
            ridge = ridges(f, u_hat, low, high, interior, full, drop)
        keep = [a for a, i in enumerate(interior) if i not in ridge]
        interior = [interior[a] for a in keep]
        hess = full[np.ix_(keep, keep)] if keep else None
        if hess is not None and not np.all(np.linalg.eigvalsh(hess) > 0):
            hess = None
    if not profile and hess is not None:
        cov = np.linalg.inv(hess)
        se = {i: float(np.sqrt(cov[a, a])) for a, i in enumerate(interior)}
    converged = bool(result.success) or stationary(f, u_hat, low, high, interior, hess)
    parameters, curves = {}, {}
    back = lambda i, u: float(u * units[i] if linear[i] else np.exp(u))  # noqa: E731
    for i, p in enumerate(free):
        falls_low, falls_high = ends[i]
        value = back(i, u_hat[i])
        identified, at_bound, note = True, False, ""
        ci_low = ci_high = None
        if i in ridge:
            identified, value = False, None
            partners = ", ".join(free[j].name for j in ridge[i])
            note = (
                f"unidentified: trades off with {partners}; the observed information along the direction that trades "
                f"them is near zero (log L changes by less than {drop:.3g} over the search range by its curvature)"
                "; only their combination is identified: the fitted filter keeps the point the search reached on the "
                "ridge"
            )
        elif not falls_low and not falls_high:
            identified, value = False, None
            note = (
                f"unidentified: log L changes by less than {drop:.3g} over [{p.lower:.3g}, {p.upper:.3g}] {p.unit}"
                "; the input setting is kept"
            ).replace(" ;", ";")
        elif not falls_low and linear[i]:
            ci_high = back(i, crossing(i, high[i]))
            note = f"no lower limit within the search range (down to {p.lower:.3g} {p.unit})".replace(" )", ")")
        elif not falls_low:
            at_bound, ci_low = True, 0.0
            ci_high = back(i, crossing(i, high[i]))
            note = f"consistent with 0: {confidence:.0%} upper limit {ci_high:.3g} {p.unit}".rstrip()
        elif not falls_high:
            ci_low = back(i, crossing(i, low[i]))
            note = f"no upper limit within the search range (up to {p.upper:.3g} {p.unit})".replace(" )", ")")
        elif i in se:
            ci_low, ci_high = back(i, u_hat[i] - z * se[i]), back(i, u_hat[i] + z * se[i])
        elif profile:
            ci_low, ci_high = back(i, crossing(i, low[i])), back(i, crossing(i, high[i]))
        else:  # the observed information is not positive definite: the profile's interval, not the slice's
            # (the slice fell at both ends; the profile, the others re-maximized, may not: a ridge), so the
            # profile is judged at each end first: None where it has not fallen to the level there
            below, above = (
                None if abs(end - u_hat[i]) < 1e-9 or profiled(i, end) > best - drop else profiled.crossing(i, end, best - drop)
                for end in (low[i], high[i])
            )
            note = "interval from the profile likelihood: the observed information is not positive definite"
            if below is None and above is None:
                identified, value = False, None
                note = (
                    f"unidentified along the profile: with the others re-maximized log L changes by less than "
                    f"{drop:.3g} over [{p.lower:.3g}, {p.upper:.3g}] {p.unit}; the input setting is kept"
                ).replace(" ;", ";")
            else:
                ci_high = None if above is None else back(i, above)
                if below is not None:
                    ci_low = back(i, below)
                elif not linear[i]:
                    at_bound, ci_low = True, 0.0
                    note += "; consistent with 0 along the profile"
                if below is None and linear[i] or above is None:
                    note += "; no limit within the search range on the side where the profile does not fall"
        partners = tuple(free[j].name for j in ridge[i]) if i in ridge else ()
        # the standard error on the search's scale (of ln(value), or of the value on a linear scale) where the
        # interval is its Wald interval, so that another level follows from it (FitResult.conf_int)
        wald = float(se[i] * units[i] if linear[i] else se[i]) if i in se and ci_low is not None else None
        parameters[p.name] = FitParameter(p.name, value, ci_low, ci_high, p.unit, p.start, identified, at_bound, note, partners,
                                          scale=p.scale, se=wald)
        # a profile's curve: half the grid, with the points its ends and crossings already profiled
        known = [v for (j, v) in profiled.known if j == i] if profile else []
        curves[p.name] = _curve(along, i, u_hat, low, high, ci_low, ci_high, curve_points // 2 + 1 if profile else curve_points,
                                float(units[i]) if linear[i] else None, known, together=not profile)
    method = "profile" if profile else "observed-information"
    message = str(result.message)
    for index, (name, curve) in enumerate(curves.items()):
        top = int(np.argmax(curve["loglik"]))
        if curve["loglik"][top] > best + BEATEN:
            if restarts > 0:
                starts = objective.values(u_hat)
                starts[index] = curve["value"][top]
                again = [replace(p, start=float(np.clip(x, p.lower, p.upper))) for p, x in zip(free, starts)]
                restarted = maximize(loglik, again, profile=profile, confidence=confidence, curve_points=curve_points,
                                     restarts=restarts - 1)
                return replace(restarted, evaluations=restarted.evaluations + objective.count)  # every search's
            converged = False
            message = (
                f"not converged: log L at {name} = {curve['value'][top]:.6g} ({curve['loglik'][top]:.10g}) beats the "
                f"reported maximum ({best:.10g}); the search stopped at a local maximum"
            )
    values = dict(zip(names, objective.values(u_hat).tolist()))
    held = [p.name for i, p in enumerate(free) if i not in interior]
    notes = ()
    if se and held:  # the observed information of the others is the conditional one: these do not share it
        notes = (
            f"the observed-information intervals hold {', '.join(held)} at the estimate (log L does not fall by "
            f"{drop:.3g} on both sides of it, or it trades off with another: no information to share)",
        )
    return MleFit(values, best, converged, parameters, curves, method, objective.count, message, notes)


def _curve(
    along, i, u_hat, low, high, ci_low, ci_high, points, unit=None, known=(), together=False
) -> dict[str, list[float]]:
    """log L along parameter i over its interval widened by half its width each way (the whole search
    range where it has no interval), in the parameter's unit (``unit``: a linear parameter's u unit):
    ``points`` evenly spaced, the estimate and the ``known`` u within that span. ``together``: the points
    are independent (a slice, not a profile's warm starts) and are evaluated together
    (:func:`~kalcal.fitting.local_search.evaluate_all`)."""
    linear = unit is not None
    if ci_low is not None and ci_high is not None and (linear or ci_low > 0):
        a, b = (ci_low / unit, ci_high / unit) if linear else (np.log(ci_low), np.log(ci_high))
        width = max(b - a, 1e-3)
        a, b = max(a - 0.5 * width, low[i]), min(b + 0.5 * width, high[i])
    else:
        a, b = low[i], high[i]
    inside = [v for v in known if a <= v <= b]
    grid = np.unique(np.concatenate([np.linspace(a, b, points), [u_hat[i]], inside]))
    loglik = np.empty(grid.size)
    order = np.argsort(np.abs(grid - u_hat[i]), kind="stable")  # outward from the maximum: a profile's warm starts
    if together:
        loglik[order] = evaluate_all(lambda v: along(i, v), list(grid[order]))
    else:
        for k in order:
            loglik[k] = along(i, grid[k])
    return {"value": (grid * unit if linear else np.exp(grid)).tolist(), "loglik": loglik.tolist()}


def point_estimate(loglik: Callable[[Mapping[str, float]], float], free: Sequence[Free]) -> tuple[dict[str, float], float, bool]:
    """The maximum of ``loglik`` over ``free`` from their starts, and nothing else: no intervals, curves,
    ridges or restarts (a bootstrap refit, :mod:`kalcal.fitting.bootstrap`, started at the fitted point).

    Returns
    -------
    values : dict of str to float
        The estimates in the parameters' units.
    loglik : float
        log L there.
    converged : bool
        L-BFGS-B's verdict, or where it stopped otherwise the stationarity test of :func:`maximize`
        (:func:`kalcal.fitting.information.stationary`, without the observed information).
    """
    names = [p.name for p in free]
    linear = np.array([p.scale == "linear" for p in free], dtype=bool)
    units = np.array([(p.upper - p.lower) / LINEAR_STEPS if p.scale == "linear" else 1.0 for p in free], dtype=float)
    objective = _Objective(loglik, names, linear, units)
    low = objective.u_of(np.array([p.lower for p in free], dtype=float))
    high = objective.u_of(np.array([p.upper for p in free], dtype=float))
    u0 = np.clip(objective.u_of(np.array([p.start for p in free], dtype=float)), low, high)
    f = lambda u: -objective.loglik_at(u)  # noqa: E731
    # stops when an iteration changes log L by about 1e-10 of itself (1e-6 at log L ~ 1e4): the estimate is
    # then within ~1e-3 of its standard error, far below a bootstrap's Monte Carlo error, in fewer iterations
    result = minimize(f, u0, low, high, ftol=REFIT_FTOL)
    u_hat = np.asarray(result.x, dtype=float)
    converged = bool(result.success) or stationary(f, u_hat, low, high, [], None)
    return dict(zip(names, objective.values(u_hat).tolist())), -float(result.fun), converged
