"""The figure of a noise fit: log-likelihood along each fitted parameter, with its interval marked."""

from __future__ import annotations

from collections.abc import Collection
from pathlib import Path

import numpy as np

from kalcal.plots._common import BAND, ESTIMATE, label, new_figure, save, styled


@styled
def plot_fit(curves: dict, parameters: dict, path: str | Path, *, method: str = "observed-information", drop: float = 1.92,
             linear: Collection[str] = ()) -> Path:
    """One panel per parameter: log L minus its maximum against the value, the estimate, the interval
    shaded and the level ``-drop`` where the interval's ends lie (:func:`fit_figure`), saved to ``path``.

    900 x (150 + 250 rows) px, two panels a row.
    """
    return save(fit_figure(curves, parameters, method=method, drop=drop, linear=linear), path)


@styled
def fit_figure(curves: dict, parameters: dict, *, method: str = "observed-information", drop: float = 1.92,
               linear: Collection[str] = ()):
    """The figure of :func:`plot_fit`: a log x axis for a setting searched on a log scale, a linear one for
    one searched on a linear scale (named in ``linear``: the job passes the latency,
    :data:`kalcal.scenarios.accel_gps.fit.LINEAR`) or with a value at or below 0, which a log axis would drop.

    Parameters
    ----------
    curves : dict
        ``{name: {"value": [...], "loglik": [...]}}`` (:attr:`kalcal.fitting.result.FitResult.curves`).
    parameters : dict
        ``{name: fit.json's parameter entry}`` (value, ci_low, ci_high, unit, identified, at_bound).
    method : str
        "observed-information" (the slice through the optimum) or "profile".
    linear : collection of str
        The settings searched on a linear scale.
    """
    names = list(curves)
    rows = max(1, (len(names) + 1) // 2)
    figure, axes = new_figure(rows, 2, sharex=False)
    along = "profile" if method == "profile" else "slice (others at the estimate)"
    for ax, name in zip(axes.flat, names):
        values = np.asarray(curves[name]["value"], dtype=float)
        loglik = np.asarray(curves[name]["loglik"], dtype=float)
        loglik = np.where(loglik < -1e299, np.nan, loglik)
        p = parameters[name]
        ax.plot(values, loglik - np.nanmax(loglik), color=ESTIMATE, marker=".", linewidth=1.2, label=f"log L, {along}")
        ax.axhline(-drop, color="black", linestyle="--", linewidth=0.8, label=f"−{drop:.3g}")
        low = p.get("ci_low")
        high = p.get("ci_high")
        on_line = name in linear or (values.size and values.min() <= 0)
        if p.get("identified"):
            left = values.min() if low is None or (low <= 0 and not on_line) else low
            right = values.max() if high is None else high
            ax.axvspan(left, right, color=BAND, alpha=0.22, label="interval")
            ax.axvline(p["value"], color=ESTIMATE, linestyle=":", linewidth=1.0)
        state = "unidentified" if not p.get("identified") else "consistent with 0" if p.get("at_bound") else f"{p['value']:.4g}"
        ax.set_title(f"{name}: {state}")
        ax.set_xscale("linear" if on_line else "log")
        ax.set_xlabel(label(name.partition(".")[2], p.get("unit", "")))
        ax.set_ylabel("log L − max")
        ax.legend(loc="lower center", fontsize=7.5)
    for ax in list(axes.flat)[len(names):]:
        ax.set_visible(False)
    return figure
