"""The smallest relative error in each of the truth's noise settings that N realizations detect, for a correct filter.

For each noise setting the truth's value is scaled by 1 + eps (an increase) or 1 - eps (a decrease)
with the filter's held, the exact analysis rerun, and the verdict's conservative power (the largest
``power_low`` of the checks, :mod:`kalcal.stats.power`) compared with ``DETECTION_POWER``. From
``START`` eps is doubled while not detected, or halved while detected (down to ``FLOOR``), then bisected
in log eps to a ratio of ``RESOLUTION`` (power taken as increasing in eps); the detected end is
reported, and ``FLOOR`` itself where even the floor is detected. The search runs first without the
whiteness check (no pair moments E[r_k r_j^T], the costly part of a rerun): that check only adds
power, so the error found is the full verdict's too unless one step of ``RESOLUTION`` below it the
full verdict (whiteness included) already detects; only then is the search continued with the pairs.
Settings: for accel-gps every positive ``truth.*_std``; for a model file the truth's ``w``, ``v`` and
``m0`` as wholes (a matrix scaled by (1 + eps)^2, so that eps is the relative error of its standard
deviations).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from kalcal.analysis.fixed_gain import analyze_scenario
from kalcal.stats.suite import check_families
from kalcal.stats.power import DETECTION_POWER

__all__ = ["FLOOR", "RESOLUTION", "START", "detected_error", "noise_settings", "sensitivity", "sensitivity_text"]

#: the first relative error tried
START = 0.005
#: the smallest relative error searched: where it is detected, the result is "at most FLOOR"
FLOOR = 1e-4
#: the search stops when the detected and undetected errors are within this ratio
RESOLUTION = 1.1
#: the largest relative increase and decrease searched (a std times 10, and times 0.1)
MAX_INCREASE, MAX_DECREASE = 9.0, 0.9


def noise_settings(scenario) -> dict[str, Callable[[float], object]]:
    """The truth's noise settings, each as factor -> the scenario with that setting's std times ``factor``
    (the filter's settings held)."""
    settings = scenario.noise_settings()
    if not settings:
        raise TypeError(f"no noise settings to scale for {type(scenario).__name__}")
    return settings


def _detects(scenario, n: int, confidence: float, form: str, pairs: bool = True) -> bool:
    analysis = analyze_scenario(scenario, form, pairs=pairs, budget=False)
    return any(check.bracket(n)[0] >= DETECTION_POWER for check in check_families(analysis, confidence))


def detected_error(detects: Callable[[float], bool], limit: float, start: float = START) -> float | None:
    """The smallest eps in [FLOOR, limit] (to RESOLUTION) with ``detects(eps)``, ``detects`` taken as
    increasing: from ``start`` doubled while not detected or halved while detected, then bisected.
    FLOOR where FLOOR is detected; None when ``limit`` is not."""
    if detects(start):
        high = start
        while True:
            if high <= FLOOR:
                return FLOOR
            low = max(high / 2.0, FLOOR)
            if not detects(low):
                break
            high = low
    else:
        low, high = start, min(2.0 * start, limit)
        while not detects(high):
            if high >= limit:
                return None
            low, high = high, min(2.0 * high, limit)
    while high / low > RESOLUTION:
        mid = float(np.sqrt(low * high))
        low, high = (low, mid) if detects(mid) else (mid, high)
    return high


def _search(detects: Callable[[float, bool], bool], limit: float) -> float | None:
    """:func:`detected_error` of ``detects(eps, pairs)``: first without the pairs, then (module docstring)
    with them only where they may detect a smaller error."""
    found = detected_error(lambda eps: detects(eps, False), limit)
    full = lambda eps: detects(eps, True)  # noqa: E731
    if found is None:
        return detected_error(full, limit)
    below = found / RESOLUTION
    if found <= FLOOR or not full(below):
        return found
    return detected_error(full, limit, start=below)


def sensitivity(scenario, n: int, confidence: float = 0.99, form: str = "joseph") -> list[dict]:
    """Per noise setting of the truth: ``{"setting", "increase", "decrease"}``, the smallest relative error
    (a fraction: 0.03 is 3%) up and down that ``n`` realizations detect with power DETECTION_POWER, FLOOR
    where even FLOOR is detected, or None where none up to a std times 10 (down to 0.1) is detected."""
    rows = []
    for key, scaled in noise_settings(scenario).items():
        up = _search(lambda eps, pairs: _detects(scaled(1.0 + eps), n, confidence, form, pairs), MAX_INCREASE)
        down = _search(lambda eps, pairs: _detects(scaled(1.0 - eps), n, confidence, form, pairs), MAX_DECREASE)
        rows.append({"setting": key, "increase": up, "decrease": down})
    return rows


def _percent(value: float) -> str:
    return f"≤{100 * FLOOR:.2g}%" if value <= FLOOR else f"{100 * value:.2g}%"


def sensitivity_text(row: dict) -> str:
    """``"accel_noise_std ±3.1%"``: the larger of the two errors (detected either way), or what is not
    detected; ``"±≤0.01%"`` where even FLOOR is detected both ways."""
    name = row["setting"].split(".", 1)[-1]
    up, down = row["increase"], row["decrease"]
    if up is None and down is None:
        return f"{name} not detected"
    if up is None or down is None:
        sign, value = ("+", up) if down is None else ("−", down)
        return f"{name} {sign}{_percent(value)}"
    return f"{name} ±{_percent(max(up, down))}"
