"""The GPS latency's log-likelihood scanned over its range: the search's start, a multimodal or an unresolved latency.

log L in ``filter.gps_latency`` is not one smooth hill: the fix is compared with the nominal at t - L,
and the nominal's shift over L sums the measured acceleration, vibration noise included, sample by
sample. Between two accelerometer samples the shift is smooth (the integration rule's polynomial), but
from sample to sample it jumps with the noise, so log L has a bump every sample period or so and, on a
noisy log, separate maxima tens of milliseconds apart (a rover-like log: within 1.92 of the maximum over
[-0.105, +0.083] s in pieces). A local search from the setting finds the nearest one and the observed
information gives it a narrow interval. So the fit scans the range on a grid of half a sample period
(:func:`scan_step`) before the search and starts from the best point, scans again at the estimate
(the others held there) and restarts once from a grid point that beats it, and takes as the interval at
least the grid's set within ``drop`` of the maximum: when that set is in separate pieces the latency is
multimodal, the interval spans them and the parameter's note says so.

That set is a 95% interval only where log L is smooth at the interval's scale. With a noisy
accelerometer it is not: moving the latency by one sample adds one noisy sample to every fix's
predicted velocity, so the curve's slope changes at random from one sample to the next (a rover-like
one-minute log: bumps of 1.5-2 in log L every 5 ms), and the maximum and the 1.92-drop set follow that
noise, not the latency. The adjacent changes themselves cannot tell: a sharp smooth hill (the default
scenario) changes by more than the drop between neighbouring grid points. Their irregular part can: a
quadratic hill, what Wilks' drop assumes, has third differences 0. So the fit measures the roughness,
the largest |third difference| of the scan over the points within twice the drop of the maximum (at
least two each side), and where it exceeds :data:`ROUGH` times the drop (a change of curvature between
neighbouring half-samples a sizeable part of the drop) the latency is **not resolved** at this log's
noise: unidentified, with no interval (:func:`judge`).

Where the model has a Gauss-Markov bias (``filter.bias_correlation_time`` above 0, the filter's or else
the truth's, or free) the latency is not resolved whatever its roughness: the coverage of its intervals
with such a bias is not established (in trials on simulated rover-like logs with less vibration, where
the roughness rule passes, some did not cover the true latency while the same logs without the bias
did; the cause is not known), so none is given (the note says why).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace

import numpy as np

from kalcal.fitting.mle import BEATEN, FAILED, Free, MleFit, drop_of, guarded

KEY = "filter.gps_latency"
#: log L is too rough for an interval where a third difference of the scan near the maximum exceeds this times the drop
ROUGH = 0.25
#: how every unresolved latency's note begins
NOT_RESOLVED = "not resolved"
#: how a latency's note begins where log L is rough at the sample scale
UNRESOLVED = "not resolved at this log's noise"
#: how a latency's note begins where the model has a Gauss-Markov bias
MARKOV = "not resolved with a Gauss-Markov bias"


def unresolved(parameter) -> bool:
    """Whether ``parameter`` (a :class:`~kalcal.fitting.result.FitParameter`) is a latency this module
    reported not resolved (held at its input)."""
    return parameter.held


def scan_step(imu_rate: float) -> float:
    """The grid's step, s: half the accelerometer's sample period (2.5 ms at 200 Hz)."""
    return 0.5 / float(imu_rate)


def scan(loglik: Callable[[Mapping[str, float]], float], values: Mapping[str, float], lower: float, upper: float,
         step: float) -> tuple[np.ndarray, np.ndarray]:
    """log L at ``values`` with the latency on an even grid from ``lower`` to ``upper`` (s) in steps of at
    most ``step``: (grid (G,),
    log L (G,)); an evaluation that fails is :data:`~kalcal.fitting.mle.FAILED`."""
    grid = np.linspace(lower, upper, int(np.ceil((upper - lower) / step - 1e-9)) + 1)  # steps of at most ``step``
    out = np.empty(grid.size)
    for n, x in enumerate(grid):
        out[n] = guarded(loglik, {**values, KEY: float(x)})
    return grid, out


def start_from_scan(loglik, parameters: Sequence[Free], step: float) -> list[Free]:
    """``parameters`` with the latency's start moved to the grid's best point, the others at their starts."""
    p = next(q for q in parameters if q.name == KEY)
    grid, values = scan(loglik, {q.name: q.start for q in parameters if q.name != KEY}, p.lower, p.upper, step)
    best = float(grid[int(np.argmax(values))])
    return [replace(q, start=best) if q.name == KEY else q for q in parameters]


def judge(loglik, fit: MleFit, parameters: Sequence[Free], step: float, confidence: float,
          refit: Callable[[float], MleFit], setting: float, markov: bool = False) -> tuple[MleFit, str]:
    """The fit with the latency's interval from the scan at the estimate: restarted once (``refit(start)``)
    from a grid point that beats the maximum, the interval widened to the grid's set within the drop
    (its ends: the first grid points outside it, none at a range end inside it), multimodal when that set
    is in pieces; unidentified, with no interval, where the scan is rough near the maximum
    (:func:`roughness` above :data:`ROUGH` times the drop) and, ``markov``, wherever the model has a
    Gauss-Markov bias (the module docstring); ``start`` reported as the ``setting`` the scan started from. Returns the fit and, when multimodal or not resolved, a sentence for the fit's notes
    ("" otherwise)."""
    p = next(q for q in parameters if q.name == KEY)
    drop = drop_of(confidence)
    for attempt in range(2):
        others = {name: value for name, value in fit.values.items() if name != KEY}
        grid, values = scan(loglik, others, p.lower, p.upper, step)
        top = int(np.argmax(values))
        if values[top] <= fit.loglik + BEATEN:
            break
        if attempt == 0:
            fit = refit(float(grid[top]))
            continue
        fit = replace(fit, converged=False, message=(
            f"not converged: log L at {KEY} = {grid[top]:.6g} ({values[top]:.10g}) beats the reported maximum "
            f"({fit.loglik:.10g}) in the scan of the latency's range"))
    parameter = replace(fit.parameters[KEY], start=setting)
    curve = fit.curves.get(KEY, {"value": [], "loglik": []})
    merged = sorted(set(zip(curve["value"], curve["loglik"])) | set(zip(grid.tolist(), values.tolist())))
    curves = {**fit.curves, KEY: {"value": [v for v, _ in merged], "loglik": [ll for _, ll in merged]}}
    said = ""
    rough = roughness(grid, values, drop)
    if parameter.identified and rough > ROUGH * drop:
        parameter = _unresolved(parameter, rough, drop, step)
        said = f"{KEY}: {parameter.note}"
    elif parameter.identified and markov:
        parameter = _markov(parameter)
        said = f"{KEY}: {parameter.note}"
    elif parameter.identified:
        parameter, pieces, span = _widened(parameter, grid, values, fit.loglik - drop, fit.values[KEY], drop, step)
        if pieces > 1:
            said = (f"{KEY}: multimodal, log L within {drop:.3g} of its maximum in {pieces} separate pieces over "
                    f"[{span[0]:.4g}, {span[1]:.4g}] s: the log does not tell the latency better than that span")
    return replace(fit, parameters={**fit.parameters, KEY: parameter}, curves=curves), said


def roughness(grid: np.ndarray, values: np.ndarray, drop: float) -> float:
    """The largest |third difference| of log L (``values``, (G,)) over the grid points within ``2 drop`` of
    its maximum, at least two either side of it (0 where fewer than four points are evaluated there)."""
    ok = values > FAILED / 2
    top = int(np.argmax(values))
    near = np.flatnonzero(values >= values[top] - 2.0 * drop)
    lo, hi = max(0, min(int(near[0]), top - 2)), min(grid.size - 1, max(int(near[-1]), top + 2))
    while not ok[lo]:
        lo += 1
    while not ok[hi]:
        hi -= 1
    failed = np.flatnonzero(~ok[lo:hi + 1])  # keep the run of evaluated points about the maximum
    if failed.size:
        below, above = failed[failed + lo < top], failed[failed + lo > top]
        lo, hi = (lo + int(below[-1]) + 1 if below.size else lo), (lo + int(above[0]) - 1 if above.size else hi)
    segment = values[lo:hi + 1]
    return float(np.max(np.abs(np.diff(segment, 3)))) if segment.size >= 4 else 0.0


def _unresolved(parameter, rough: float, drop: float, step: float):
    """The latency unidentified: log L too rough at the sample scale for its drop set to be an interval."""
    note = (
        f"{UNRESOLVED}: log L in the latency is rough at the accelerometer's sample scale (its curvature changes by up "
        f"to {rough:.3g} between neighbouring points of a {step * 1e3:.3g} ms grid near the maximum, more than "
        f"{ROUGH:g} x {drop:.3g}), so its maximum and {drop:.3g}-drop set follow the vibration noise of single samples, "
        "not the latency: no interval is given; the input setting is kept"
    )
    return _unidentified(parameter, note)


def _markov(parameter):
    """The latency unidentified: the model has a Gauss-Markov bias, with which its intervals did not cover."""
    note = (
        f"{MARKOV}: the coverage of its intervals with such a bias is not established (on simulated logs some did "
        "not cover the true latency), so none is given; the input setting is kept"
    )
    return _unidentified(parameter, note)


def _unidentified(parameter, note: str):
    """``parameter`` held at its input: no value and no interval, unidentified, saying ``note``."""
    return replace(parameter, value=None, ci_low=None, ci_high=None, identified=False, at_bound=False, note=note, held=True, se=None)


def _widened(parameter, grid, values, level, estimate, drop, step):
    """The parameter with its interval at least the grid's set within ``drop``, the set's pieces (more than
    one: multimodal) and the span of the set (s)."""
    within = values >= level
    within[int(np.argmin(np.abs(grid - estimate)))] = True  # the estimate is in the set, whatever the grid
    index = np.flatnonzero(within)
    pieces = 1 + int(np.count_nonzero(np.diff(index) > 1))
    low = None if index[0] == 0 else float(grid[index[0] - 1])
    high = None if index[-1] == grid.size - 1 else float(grid[index[-1] + 1])
    ci_low = None if low is None or parameter.ci_low is None else min(parameter.ci_low, low)
    ci_high = None if high is None or parameter.ci_high is None else max(parameter.ci_high, high)
    notes = [parameter.note] if parameter.note else []
    if pieces > 1:
        notes.append(
            f"multimodal: log L in the latency (the others at the estimate) is within {drop:.3g} of its maximum in "
            f"{pieces} separate pieces of [{grid[index[0]]:.4g}, {grid[index[-1]]:.4g}] s (a {step * 1e3:.3g} ms grid over "
            "the range); the interval spans them and the value is only the highest of them"
        )
    elif (ci_low, ci_high) != (parameter.ci_low, parameter.ci_high):
        notes.append(f"interval widened to where log L along the latency stays within {drop:.3g} of its maximum "
                     f"(a {step * 1e3:.3g} ms grid over the range)")
    span = (float(grid[index[0]]), float(grid[index[-1]]))
    # a widened interval is the grid's set, no longer the Wald one: no other level follows from a standard error
    se = parameter.se if (ci_low, ci_high) == (parameter.ci_low, parameter.ci_high) else None
    return replace(parameter, ci_low=ci_low, ci_high=ci_high, note="; ".join(notes), se=se), pieces, span

