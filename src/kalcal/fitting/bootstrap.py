"""Parametric bootstrap of a maximum-likelihood fit: B logs simulated from the fitted model, each refitted.

For replicate b = 0..B-1 the scenario draws one log from its fitted model with the user's log's length,
sampling, missing measurements and inputs (``draw(rng)``, the scenario's hook: it returns that log's
log-likelihood as a function of the settings), and the fit's search refits it as a point estimate only
(:func:`kalcal.fitting.mle.point_estimate`: L-BFGS-B started at the fitted point, no intervals, curves or
profiles). From the B estimates theta*_b of each setting:

* the percentile interval [q_{alpha/2}, q_{1-alpha/2}] of theta*_b, alpha = 1 - confidence (Efron), the
  quantile q_p the (B + 1) p-th smallest refit (interpolated between order statistics where (B + 1) p is not
  whole: numpy's ``weibull`` method). For an estimator whose spread is SYMMETRIC about the truth as the
  refits' is about the estimate (theta_hat - theta and theta*_b - theta_hat of one law F, symmetric about 0,
  on the setting's scale or some monotone transformation of it: a symmetric pivot), the k-th smallest of B
  refits lies above the truth with probability k/(B + 1) exactly, so that each end's level is the one stated
  whatever B. Only then: the refits' spread mirrors the estimate's, which is the estimate's own only where F
  is symmetric, and a skewed pivot's interval covers less (F = Exp(1) - 1, B = 39 at 95%: 86%). numpy's
  default (the 1 + (B - 1) p-th smallest) is nearer the middle: with B = 39 at 95% a symmetric pivot's
  interval from it covers 90%, with B = 19 at 90%, 82%;
* the bootstrap standard error, the sample std of theta*_b (ddof = 1), in the setting's unit;
* the estimator's bias, mean(theta*_b) - theta_hat, with its own Monte Carlo standard error se / sqrt(B).

A setting whose estimate is at its lower bound ("consistent with 0") gets no interval: the percentile
bootstrap is not consistent when the true value is on the boundary of the parameter space (Andrews 2000,
Econometrica 68(2) 399-405). Nor does one NEAR its bound: where a percentile end's quantile rests on refits
that stopped at an end of the search range that stands for a bound of the parameter space (a log-scale
setting's floor, the variance's 0: those refits are consistent with 0; either end of a ``bounded`` linear
range, such as an AR(1) coefficient's [-1, 1]), the estimate is within the estimator's spread of the bound,
where the percentile interval's ends are not valid (Andrews 2000). A refit is at an end of its range
(:func:`snap_to_bounds`) where it stopped within 1e-6 (relative) of it, or where log L with the setting at
that end, the others held at the refit's own values, is as high as the refit's own log L, to what the
refit's search resolves (``REFIT_FTOL`` max(|log L|, 1)), or higher (of the two ends, the higher): the end is as
good a maximum along the setting, it becomes the refit's value, and the refit counts at that end. That
catches the refits L-BFGS-B stops short of the bound: a variance's log L flattens on the log scale as it
nears 0 and the search stops on the flatness (1.1e-6 for a floor at 1e-6, log L there 3e-7 higher). Where
log L is as high at both ends (or as high at one and failing at the other), the refit does not tell the
setting: it is not moved, and the entry gets no interval (its refits' values would be where their searches
stopped). Judged with the others at the refit,
the moves are applied together where log L at the joint point is as high as the refit's, else only the one
whose end has the highest log L, so the result does not depend on the settings' order. A refit whose log L
at the end is lower beyond that resolution has its maximum inside the range (log L rises from the bound): it
is not at the bound, however near it lies. An entry whose percentile ends coincide (refits that do not
spread, whatever the reason) gets no interval either. (A rule calling a refit at the bound where log L at the end is
within chi2(c, 1)/2 of its maximum, "consistent with 0", would flag interior fixtures: a (1 - c)/2 quantile
about z_{(1+c)/2} se below the estimate is itself consistent with 0 wherever the estimate is within about
2 z_{(1+c)/2} se of 0, far stricter than Andrews' condition, a truth on or within the estimator's spread of
the bound.)
A percentile end resting on refits stopped at an end of the search range that is NOT a bound (a variance's
ceiling: the log scale does not bound it above; a latency's search range) is that range's end, not a
quantile, and the other end alone holds no stated level there: over all logs a c interval's lower end
covers at (1 + c)/2 (for an estimator symmetric about the truth), but the logs that lose the upper end are those whose estimate is high, where a lower
bound misses most, so among them, the only logs where it would be shown alone, it covers less (a normal
estimator whose ceiling is near the truth, in the tests: 145 of 192 such logs, 76%, where it would say
87.5%; 1266 of 1319, 96.0%, where it would say 97.5%). Such an entry is "not applicable" (no interval and
no level), its reason naming the end at the range's end; with both ends lost there is none either.
One whose likelihood interval has no limit on one side within the search range gets none either: at a bound
that side is the bound's case; elsewhere the log does not bound the setting on that side, so refits run to the range's end and a percentile end there would
be the range, not a quantile. Each such entry says "not applicable" and why, and keeps the se, bias and refits.
A setting that is unidentified or not resolved is held at its input in every refit, one that trades off with
others at the fitted point: its entry says "not applicable" and why, without se, bias or refits.

Seeds: replicate b draws from the Monte Carlo engine's generator of block b
(:func:`kalcal.montecarlo.engine.block_generator`, ``SeedSequence(seed, spawn_key=(b,))``), and the
replicates' estimates are kept in b order, so a seed gives the same intervals whatever runs them: one
thread, several, or Dask tasks (``client``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from kalcal.errors import KalcalError
from kalcal.fitting.mle import FAILED, REFIT_FTOL, Free, point_estimate

#: the reference for "not applicable" at a bound
ANDREWS = "Andrews 2000: the percentile bootstrap is not consistent when the true value is on the boundary of the parameter space"

#: the reason of an entry whose percentile end rests on refits at a bound of the parameter space ({at}: what
#: the bound is)
NEAR_BOUND = ("near its bound: refits at the bound ({at}) reach the interval's end; the percentile interval is not "
              "valid near a bound (Andrews 2000)")


def boundary_ends(spec: Free) -> tuple[bool, bool]:
    """Whether each end of ``spec``'s search range, (lower, upper), stands for a bound of the parameter space.

    A log-scale setting (a variance, a std, a time constant) is bounded below by 0, which its search's floor
    (a factor below the start) stands for; nothing bounds it above, so its ceiling is only where the search
    stops. A linear-scale range is a bound at both ends where it is ``bounded`` (phi's [-1, 1]), at neither
    otherwise."""
    if spec.scale == "log":
        return True, False
    return spec.bounded, spec.bounded


def _bound_text(spec: Free, side: str) -> str:
    """What the bound at ``side`` of ``spec``'s range is, for :data:`NEAR_BOUND`."""
    if spec.scale == "log":
        return "consistent with 0"
    return f"at {spec.lower if side == 'lower' else spec.upper:g}"


#: the scenario's hook: a log drawn with ``rng`` from the fitted model, returned as its log-likelihood
Draw = Callable[[np.random.Generator], Callable[[Mapping[str, float]], float]]


@dataclass(frozen=True)
class BootstrapParameter:
    """One setting's bootstrap summary.

    Attributes
    ----------
    name : str
    applicable : bool
        False where no bootstrap interval is given (``reason`` says why).
    reason : str
        Why not applicable ("" otherwise).
    ci_low, ci_high : float or None
        The percentile interval at the fit's confidence c, in the setting's unit; both None where not
        applicable. An applicable entry has both ends: where an end's quantile is a refit that stopped at an
        end of the search range, the entry is not applicable, near its bound where that range end is a bound
        of the parameter space (a variance's floor, 0), and otherwise (a variance's ceiling) because the other
        end alone does not hold a stated level there (module docstring: no one-sided bound is offered).
    se : float or None
        The bootstrap standard error: std of the refits (ddof = 1), the setting's unit.
    bias : float or None
        mean(refits) - estimate, the setting's unit: the estimator's bias at the fitted model.
    bias_se : float or None
        The Monte Carlo standard error of ``bias``: se / sqrt(B).
    at_range_end : int
        Refits at an end of the search range: at a bound (a variance's floor) a maximum on the boundary,
        consistent with 0, whether the search reached it or stopped short of it on a flat log L
        (:func:`snap_to_bounds`); at an end that is no bound, that end, not a maximum.
    values : tuple of float
        The refits' estimates in replicate order (for the figure; in fit.json too).
    """

    name: str
    applicable: bool
    reason: str = ""
    ci_low: float | None = None
    ci_high: float | None = None
    se: float | None = None
    bias: float | None = None
    bias_se: float | None = None
    at_range_end: int = 0
    values: tuple[float, ...] = ()

    def as_dict(self) -> dict[str, Any]:
        return {"applicable": self.applicable, "reason": self.reason, "ci_low": self.ci_low, "ci_high": self.ci_high,
                "se": self.se, "bias": self.bias, "bias_se": self.bias_se, "at_range_end": self.at_range_end,
                "values": list(self.values)}


@dataclass(frozen=True)
class BootstrapResult:
    """The parametric bootstrap of one fit (module docstring).

    Attributes
    ----------
    replicates : int
        B, the logs simulated and refitted.
    seed : int
        The root seed of the replicates' generators.
    confidence : float
        Of the percentile intervals (the fit's).
    parameters : dict of str to BootstrapParameter
        By setting, in the fit's order.
    failed : int
        Refits whose search did not report convergence (their estimates are kept: the search's last point).
    seconds : float
        Wall time of the B simulations and refits.
    """

    replicates: int
    seed: int
    confidence: float
    parameters: dict[str, BootstrapParameter] = field(default_factory=dict)
    failed: int = 0
    seconds: float = 0.0

    def as_dict(self) -> dict[str, Any]:
        return {"method": "parametric, percentile intervals", "replicates": self.replicates, "seed": self.seed,
                "confidence": self.confidence, "not_converged": self.failed, "seconds": self.seconds,
                "parameters": {name: p.as_dict() for name, p in self.parameters.items()}}


def minimum_replicates(confidence: float) -> int:
    """The fewest replicates B whose percentile interval at ``confidence`` c has its ends among the refits.

    The c interval's lower end is the k-th smallest refit, k = (B + 1)(1 - c)/2 (module docstring), which
    exists only where k >= 1, i.e. B >= 2/(1 - c) - 1. At that fewest B, where 2/(1 - c) is whole, the ends are
    the smallest and largest refits (39 at 95%: the smallest and largest of 39; 19 at 90%); elsewhere k is just
    above 1 and the ends lie between the two smallest and the two largest refits (13 at 85%). Fewer, and k < 1: the
    level asks for a quantile beyond the smallest refit, which the sample's range would stand in for, whatever
    c says.
    """
    # the small allowance, relative (the rounding of 1 - c grows with 1/(1 - c)), keeps 2/(1 - 0.95) - 1,
    # 39.00000000000004 in floating point, at 39, and 0.99999's 199999.0000013 at 199999
    least = 2.0 / (1.0 - confidence) - 1.0
    return max(2, math.ceil(least - 1e-9 * max(1.0, least)))


#: the most replicates a bootstrap runs. At B = 1e5 a 95% percentile end's own Monte Carlo error,
#: sqrt(0.025 x 0.975 / B) / phi(1.96) ~ 0.009 bootstrap se for a normal estimator, is under 1% of the
#: spread it measures, and the refits' values (kept in memory and fit.json) are ~1e5 per setting already:
#: more buys nothing the interval can show, at the cost of hours and memory (1e12 would not fit in memory)
MAX_REPLICATES = 100_000


def whole_number(value) -> bool:
    """Whether ``value`` is a finite whole number (not a bool): 40 and 40.0, not nan, inf, 40.5 or "40"."""
    if isinstance(value, bool):
        return False
    try:
        return math.isfinite(value) and int(value) == value
    except (TypeError, ValueError, OverflowError):
        return False


def check_replicates(replicates, confidence: float) -> None:
    """Raise KalcalError, one line, unless ``replicates`` is a whole number within
    [:func:`minimum_replicates`, :data:`MAX_REPLICATES`]; where that range is empty (c above 1 - 2/100001,
    0.99998), say that no B serves the level."""
    least = minimum_replicates(confidence)
    # the level with the digits it has (0.99999, not 0.99999's "1" at 4 significant digits)
    level = f"{confidence:.12g}"
    if least > MAX_REPLICATES:
        raise KalcalError(f"--bootstrap: no B within {MAX_REPLICATES} replicates serves a {level} percentile interval: "
                          f"it needs B >= {least} ((B + 1)(1 - c)/2 >= 1), got {replicates!r}")
    if not whole_number(replicates) or replicates < least:
        raise KalcalError(f"--bootstrap: a {level} percentile interval needs at least {least} replicates "
                          f"((B + 1)(1 - c)/2 >= 1), got {replicates!r}")
    if replicates > MAX_REPLICATES:
        raise KalcalError(f"--bootstrap: at most {MAX_REPLICATES} replicates (there a percentile end's Monte Carlo "
                          f"error is under 1% of the bootstrap se; more costs hours and memory), got {replicates!r}")


#: numpy's quantile method of the percentile ends: the (B + 1) p-th smallest of B (module docstring)
QUANTILE_METHOD = "weibull"


def _order_statistics(replicates: int, q: float) -> list[int]:
    """The (0-based) order statistics of ``replicates`` values that the quantile ``q`` (:data:`QUANTILE_METHOD`,
    the (B + 1) q-th smallest, 1-based) rests on."""
    position = min(max((replicates + 1) * q - 1.0, 0.0), replicates - 1.0)
    # (B + 1) q is whole at the B the levels are chosen for (40 x 0.025): 1e-15 of rounding is no interpolation
    if abs(position - round(position)) < 1e-9:
        position = float(round(position))
    return sorted({math.floor(position), math.ceil(position)})


def _held_reason(p) -> str:
    """Why a setting of the fit is not refitted: it trades off with others, is not resolved, or is unidentified."""
    return "trades off with " + ", ".join(p.trades_off) if p.trades_off else "not resolved" if p.held else "unidentified"


def snap_to_bounds(
    loglik: Callable[[Mapping[str, float]], float], free: Sequence[Free], values: Mapping[str, float], best: float
) -> tuple[dict[str, float], list[tuple[bool, bool]], set[str]]:
    """A refit's values with each setting whose log L is as high at an end of its search range moved there.

    Each setting of ``free`` is judged from the refit's own point, the others held at the refit's values, so
    that the result does not depend on the settings' order:

    * within 1e-6 (relative) of an end of its search range, it is at that end (no evaluation);
    * otherwise log L is evaluated with the setting at each end of its range (:func:`kalcal.fitting.mle.guarded`),
      and compared with ``best`` to the refit's own resolution, ``REFIT_FTOL`` |log L| (its search stops where an
      iteration changes log L by that much: a value within it is as high as the refit's, to what the search
      can tell). Where log L at an end is as high as at the refit or higher, that end is as good a maximum
      along the setting (the search stopped short of it on a log L that is flat near it, or the end is the
      higher point): the setting moves to the end where log L is highest and counts at it (at a bound of the
      parameter space, a variance's floor or phi's +-1, the refit is then "consistent with the bound"; at an
      end that bounds nothing, a variance's ceiling or a latency's range end, the refit ran to the range's
      end);
    * where log L is as high at both ends (each as high as at the refit or higher, and the two within the
      resolution of each other), or as high (not higher) at one end and failing (:data:`kalcal.fitting.mle.FAILED`)
      at the other, the refit does not tell the setting: it is neither moved nor counted at an end, and is
      returned among the flat settings (the bootstrap then gives that setting no interval). An end where
      log L fails is no maximum.

    The resolution is ``REFIT_FTOL`` max(|log L|, 1).

    The moves (one end per setting) are applied together where log L at the joint point is as high as at
    the refit (each move was judged with the others at the refit, and two moves can undo each other);
    otherwise only the one with the highest log L at its end is (ties broken by the setting's name, so the
    order of ``free`` does not matter). Either way the returned point's log L is the refit's or higher, to the
    refit's resolution.

    Parameters
    ----------
    loglik : callable
        The replicate's log-likelihood, ``loglik({name: value})``.
    free : sequence of Free
        The refit's settings and their search ranges.
    values : mapping of str to float
        The refit's estimates, in the settings' units.
    best : float
        log L at ``values``.

    Returns
    -------
    values : dict of str to float
        The refit's values, the settings moved to an end where log L is as high there or higher.
    at_end : list of (bool, bool)
        Per setting of ``free``: whether the refit is at the lower and at the upper end of its range.
    flat : set of str
        The settings along which log L is as high at both ends as at the refit (not told by this refit).
    """
    from kalcal.fitting.mle import guarded

    refit = dict(values)
    at_end = {p.name: [math.isclose(refit[p.name], end, rel_tol=1e-6, abs_tol=0.0) for end in (p.lower, p.upper)]
              for p in free}
    moves: dict[str, tuple[int, float]] = {}  # setting -> (end index, log L there)
    flat: set[str] = set()
    # what the refit's own search resolves of log L: it stops where an iteration changes log L by REFIT_FTOL of
    # itself, so a value within this of ``best`` is as high as the refit's, to what the search can tell
    resolution = REFIT_FTOL * max(abs(best), 1.0)
    for p in free:
        if any(at_end[p.name]):
            continue
        there = [guarded(loglik, {**refit, p.name: end}) for end in (p.lower, p.upper)]
        passing = [k for k in (0, 1) if there[k] >= best - resolution]
        failed = [k for k in (0, 1) if there[k] <= FAILED]
        if len(passing) == 2 and abs(there[0] - there[1]) <= resolution:
            flat.add(p.name)  # as high at both ends: the refit does not tell the setting
        elif len(passing) == 1 and failed and there[passing[0]] <= best + resolution:
            # as high at one end, log L failing at the other: nothing shows where along the setting its
            # maximum is (the end would be as arbitrary a point as the refit's)
            flat.add(p.name)
        elif passing:
            k = max(passing, key=lambda k: there[k])  # the end where log L is highest: the better point
            moves[p.name] = (k, there[k])
    if not moves:
        return refit, [tuple(at_end[p.name]) for p in free], flat
    range_of = {p.name: (p.lower, p.upper) for p in free}
    joint = {**refit, **{name: range_of[name][k] for name, (k, _) in moves.items()}}
    if len(moves) > 1 and guarded(loglik, joint) < best - resolution:
        # the moves undo each other together: the single one with the highest log L at its end, still as high
        keep = max(sorted(moves), key=lambda name: moves[name][1])
        moves = {keep: moves[keep]}
        joint = {**refit, keep: joint[keep]}
    for name, (k, _) in moves.items():
        at_end[name][k] = True
    return joint, [tuple(at_end[p.name]) for p in free], flat


def _replicate(draw: Draw, free: Sequence[Free], seed: int, index: int) -> tuple[list[float], bool, list[tuple[bool, bool, bool]]]:
    """Replicate ``index``: its log drawn from block ``index``'s generator, refitted from the fitted point, each
    setting whose log L is as high at an end of its range moved there (:func:`snap_to_bounds`); with the
    refit's convergence and per setting whether it is at the (lower, upper) end of its range and whether log L
    is flat along it."""
    from kalcal.fitting import local_search
    from kalcal.montecarlo.engine import block_generator

    # the parallelism is across replicates: a refit's gradient runs its evaluations here, one after another
    # (and back as it was after: on a Dask worker's thread, reused by the user's later fits, it would stay set)
    before = getattr(local_search._IN_POOL, "active", False)
    local_search._IN_POOL.active = True
    try:
        loglik = draw(block_generator(seed, index))
        values, best, converged = point_estimate(loglik, free)
        values, at_end, flat = snap_to_bounds(loglik, free, values, best)
    finally:
        local_search._IN_POOL.active = before
    return [values[p.name] for p in free], converged, [(*ends, p.name in flat) for p, ends in zip(free, at_end)]


def parametric_bootstrap(
    draw: Draw,
    free: Sequence[Free],
    fit,
    replicates: int,
    *,
    seed: int = 0,
    confidence: float = 0.95,
    threads: int | None = None,
    client=None,
    progress: Callable[[int, int], None] | None = None,
) -> BootstrapResult:
    """B = ``replicates`` logs drawn by ``draw`` and refitted over ``free`` from ``fit``'s point (module docstring).

    Parameters
    ----------
    draw : callable
        ``draw(rng)`` -> ``loglik(values)``: one log simulated from the fitted model (the values the fit
        reported; the settings not free as the fit held them), as its log-likelihood.
    free : sequence of Free
        The search's parameters (ranges and scales); the refits start at ``fit.values``.
    fit : MleFit
        The fit of the user's log: its ``values`` and ``parameters`` (identified, at a bound).
    replicates : int
        B >= :func:`minimum_replicates` of ``confidence`` (39 at 95%).
    seed : int
        Replicate b draws from ``SeedSequence(seed, spawn_key=(b,))``.
    confidence : float
        Of the percentile intervals.
    threads : int, optional
        Local threads (default: the CPUs this process may use).
    client : dask.distributed.Client, optional
        Run the replicates as Dask tasks instead.
    progress : callable, optional
        ``progress(done, B)``.
    """
    from kalcal.cpus import usable_cpus

    from kalcal.montecarlo.engine import check_seed

    check_replicates(replicates, confidence)
    check_seed(seed)
    replicates = int(replicates)
    refit = [replace(p, start=float(np.clip(fit.values[p.name], p.lower, p.upper))) for p in free
             if fit.parameters[p.name].identified and not fit.parameters[p.name].trades_off
             and not fit.parameters[p.name].held]
    if not refit:
        # nothing to refit: every replicate would be the fitted point itself, so no setting has a distribution
        held = ", ".join(f"{name} ({_held_reason(p)})" for name, p in fit.parameters.items())
        raise KalcalError(f"--bootstrap: no free setting is identified, so there is nothing to refit: {held}")
    started = time.perf_counter()
    rows: list[tuple[list[float], bool, list[tuple[bool, bool]]] | None] = [None] * replicates
    if client is not None:
        futures = client.map(_replicate, [draw] * replicates, [refit] * replicates, [seed] * replicates,
                             range(replicates), pure=False)
        for b, future in enumerate(futures):
            rows[b] = future.result()
            if progress is not None:
                progress(b + 1, replicates)
    else:
        workers = max(1, min(replicates, threads or usable_cpus()))
        with ThreadPoolExecutor(max_workers=workers) as pool:
            futures = [pool.submit(_replicate, draw, refit, seed, b) for b in range(replicates)]
            for b, future in enumerate(futures):
                rows[b] = future.result()
                if progress is not None:
                    progress(b + 1, replicates)
    seconds = time.perf_counter() - started
    estimates = np.array([row[0] for row in rows], dtype=float).reshape(replicates, len(refit))
    failed = sum(not row[1] for row in rows)
    # (replicate, setting, k): whether the refit is at the lower (k = 0) or upper (1) end of the setting's
    # range, and (2) whether its log L is flat along the setting (snap_to_bounds)
    ends_of = np.array([row[2] for row in rows], dtype=bool).reshape(replicates, len(refit), 3)
    parameters = {}
    column = {p.name: j for j, p in enumerate(refit)}
    for name, p in fit.parameters.items():
        if name not in column:
            kept = "the fitted point" if p.trades_off else "its input"
            parameters[name] = BootstrapParameter(name, False, f"{_held_reason(p)}: held at {kept} in every refit")
            continue
        spec = refit[column[name]]
        draws = estimates[:, column[name]]
        at_range = {"lower": ends_of[:, column[name], 0], "upper": ends_of[:, column[name], 1]}
        ends = int(np.count_nonzero(at_range["lower"] | at_range["upper"]))
        se = float(np.std(draws, ddof=1))
        summary = dict(se=se, bias=float(np.mean(draws) - fit.values[name]), bias_se=se / float(np.sqrt(replicates)),
                       at_range_end=ends, values=tuple(draws.tolist()))
        flat = int(np.count_nonzero(ends_of[:, column[name], 2]))
        if p.at_bound:
            reason = f"at its lower bound (consistent with 0): no percentile interval ({ANDREWS})"
            parameters[name] = BootstrapParameter(name, False, reason, **summary)
        elif flat:
            # such a refit's value is where its search stopped, not an estimate: its quantiles would be no
            # quantiles of the estimator (all of them flat: an interval of zero width)
            reason = (f"{flat} of {replicates} refits do not tell it: their log L is as high at both ends of its search "
                      "range (or at one, failing at the other), so their values are where the search stopped: no "
                      "percentile interval")
            parameters[name] = BootstrapParameter(name, False, reason, **summary)
        elif p.ci_low is None or p.ci_high is None:
            side = "lower" if p.ci_low is None else "upper"
            if boundary_ends(spec)[side == "upper"]:
                reason = (f"no likelihood limit on the {side} side within the search range, which ends at a bound: "
                          + NEAR_BOUND.format(at=_bound_text(spec, side)))
            else:
                reason = ("no likelihood limit on one side within the search range: the log does not bound it there, "
                          "so refits run to the range's end and a percentile end would be the range: no percentile interval")
            parameters[name] = BootstrapParameter(name, False, reason, **summary)
        else:
            tail = (1.0 - confidence) / 2.0
            low, high = np.quantile(draws, [tail, 1.0 - tail], method=QUANTILE_METHOD)
            # an end whose quantile rests on a refit stopped at an end of the search range is that end, not a quantile
            order = np.argsort(draws, kind="stable")
            # per percentile end, the range ends its order statistics' refits stopped at
            touched = {side: [end for end in ("lower", "upper") if at_range[end][order[_order_statistics(replicates, q)]].any()]
                       for side, q in (("lower", tail), ("upper", 1.0 - tail))}
            lost = [side for side in ("lower", "upper") if touched[side]]
            bounds = dict(zip(("lower", "upper"), boundary_ends(spec)))
            at_bound = [end for side in lost for end in touched[side] if bounds[end]]
            if at_bound:
                # refits at a bound (consistent with 0) reach the end: the estimate is near the bound, where
                # the percentile interval is not valid (Andrews 2000), whatever its other end says: no interval
                reason = NEAR_BOUND.format(at=_bound_text(spec, at_bound[0]))
                parameters[name] = BootstrapParameter(name, False, reason, **summary)
            elif len(lost) == 2:
                reason = ("both ends at the search range's ends: their quantiles are refits that stopped there, where "
                          "the log does not bound the setting: no percentile interval")
                parameters[name] = BootstrapParameter(name, False, reason, **summary)
            elif lost:
                # the other end alone holds no stated level: where one end is lost (the logs whose refits reach
                # the range's end, the high or low estimates) the kept end misses more often than (1 + c)/2
                # (module docstring: measured below it), so it is not offered as a one-sided bound either
                side = lost[0]
                kept = "upper" if side == "lower" else "lower"
                reason = (f"one end at the search range's end: the {side} end is at the search range's end "
                          f"({spec.lower if side == 'lower' else spec.upper:.4g}), its quantile a refit that stopped there, "
                          f"where the log does not bound the setting (no bound of the parameter space), and the {kept} "
                          f"end alone holds no stated level there: where the {side} end is lost it covers less often "
                          f"than {100.0 * (1.0 + confidence) / 2.0:g}%, so no percentile interval")
                parameters[name] = BootstrapParameter(name, False, reason, **summary)
            elif not high > low:
                # refits that do not spread (a log L flat where no end shows it, or failing at both ends): an
                # interval of zero width would claim the setting exactly
                reason = (f"the refits do not spread: the percentile ends are both {float(low):.4g}, so the log does not "
                          "tell the setting in them: no percentile interval")
                parameters[name] = BootstrapParameter(name, False, reason, **summary)
            else:
                parameters[name] = BootstrapParameter(name, True, "", float(low), float(high), **summary)
    return BootstrapResult(replicates, int(seed), float(confidence), parameters, failed, seconds)


def bootstrap_fit(options, draw: Draw, free: Sequence[Free], fit, confidence: float) -> BootstrapResult | None:
    """The bootstrap ``options`` ask for (:class:`~kalcal.fitting.run.FitOptions`: ``bootstrap`` B, ``seed``,
    ``threads``, ``client``, ``confidence``), or None where B is 0: what each scenario's fit calls with its own
    ``draw`` and the ``confidence`` of ``fit``'s likelihood intervals.

    Raises KalcalError where ``options.confidence`` is not ``confidence``: the percentile interval would be
    printed beside a likelihood interval of another level, and judged by that interval's limits."""
    replicates = getattr(options, "bootstrap", 0) or 0
    if not replicates:
        return None
    if options.confidence != confidence:
        raise KalcalError(f"confidence: the fit's intervals at {confidence:.12g} and the bootstrap's at "
                          f"{options.confidence:.12g} differ: give one level (FitOptions.confidence and confidence=)")
    return parametric_bootstrap(draw, free, fit, replicates, seed=options.seed, confidence=options.confidence,
                                threads=options.threads, client=options.client)
