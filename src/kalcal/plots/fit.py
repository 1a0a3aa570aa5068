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


@styled
def plot_bootstrap(result, path: str | Path) -> Path:
    """Each fitted setting's parametric bootstrap distribution (:func:`bootstrap_figure`), saved to ``path``.

    900 x (150 + 250 rows) px, two panels a row."""
    return save(bootstrap_figure(result), path)


#: the fewest decades the drawn values span for a log axis: two, so that at least two decade ticks lie on it,
#: each labelled with its number; over a narrower span a log axis may hold no decade tick at all (and its
#: minor ticks' labels overprint each other), so the axis is linear there
LOG_AXIS_DECADES = 2.0


@styled
def bootstrap_figure(result):
    """One panel per setting of ``result`` (a :class:`~kalcal.fitting.result.FitResult` with its
    ``bootstrap``), in its order: the histogram of the B refits' estimates, the estimate, the likelihood
    interval (the fit's method) shaded with solid lines at its ends (``gid`` "likelihood-interval"; an
    estimate consistent with 0 has 0 as its lower end, drawn on a linear axis only) and the percentile
    interval's ends as dashed lines (``gid`` "percentile-interval") where it applies (an applicable entry has
    both ends). Where it does not, the title says "not applicable" and why, in short (the reason in full is the table's and fit.json's); a
    setting held in every refit has no histogram, only its reason.

    The x axis is logarithmic for a setting searched on a log scale whose drawn values (refits, estimate,
    interval ends) are positive and span :data:`LOG_AXIS_DECADES` decades or more, linear otherwise: either
    way it carries numbered ticks."""
    import textwrap

    from matplotlib.ticker import MaxNLocator, NullFormatter

    boot = result.bootstrap
    names = list(boot.parameters)
    rows = max(1, (len(names) + 1) // 2)
    figure, axes = new_figure(rows, 2, sharex=False)
    for ax, name in zip(axes.flat, names):
        b, p = boot.parameters[name], result.parameters[name]
        ax.set_xlabel(label(name.partition(".")[2], p.unit))
        ax.set_ylabel("refits")
        if not b.values:
            ax.set_title(f"{name}: not applicable", fontsize=9)
            ax.text(0.5, 0.5, textwrap.fill(b.reason, 60), ha="center", va="center", fontsize=8, transform=ax.transAxes)
            ax.set_xticks([])
            ax.set_yticks([])
            continue
        values = np.asarray(b.values, dtype=float)
        drawn = np.array([x for x in (*values, p.value, p.ci_low, p.ci_high, b.ci_low, b.ci_high) if x is not None])
        positive = drawn[drawn > 0]
        log_axis = (p.scale == "log" and values.min() > 0 and positive.size > 0
                    and np.log10(positive.max() / positive.min()) >= LOG_AXIS_DECADES)
        if values.max() == values.min():  # every refit at one point (a flat direction): one bar about it
            half = 0.05 * abs(values[0]) or 0.5
            bins = [values[0] - half, values[0] + half]
        else:
            bins = np.geomspace(values.min(), values.max(), 31) if log_axis else 30
        ax.hist(values, bins=bins, color=ESTIMATE, alpha=0.55, label=f"{boot.replicates} bootstrap refits")
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))  # counts of refits
        if p.value is not None:
            ax.axvline(p.value, color="black", linewidth=1.2, label="estimate")
        ends = [end for end in (p.ci_low, p.ci_high) if end is not None and (end > 0 or not log_axis)]
        if p.ci_high is not None:
            # a lower end of 0 (consistent with 0) or none: the band runs from the leftmost thing drawn
            left = p.ci_low if p.ci_low in ends else min(values.min(), p.value if p.value is not None else values.min())
            ax.axvspan(left, p.ci_high, color=BAND, alpha=0.22, label=f"{result.interval_method} interval")
        for end in ends:
            ax.axvline(end, color=BAND, linewidth=1.4, gid="likelihood-interval")
        if b.applicable:
            for end in (b.ci_low, b.ci_high):
                ax.axvline(end, color="tab:red", linestyle="--", linewidth=1.0, gid="percentile-interval")
            ax.plot([], [], color="tab:red", linestyle="--", label=f"{boot.confidence:.0%} percentile interval")
            title = f"{name}: bias {b.bias:.3g} ± {b.bias_se:.2g}"
        else:
            title = f"{name}: percentile interval not applicable"
        why = _short_reason(b.reason)
        ax.set_title(title + (f"\n{why}" if why else ""), fontsize=9)
        ax.set_xscale("log" if log_axis else "linear")
        if log_axis:  # two decades or more: the decades' numbers label it; minor labels would overprint
            ax.xaxis.set_minor_formatter(NullFormatter())
        ax.legend(loc="upper right", fontsize=7)
    for ax in list(axes.flat)[len(names):]:
        ax.set_visible(False)
    return figure


def _short_reason(reason: str) -> str:
    """A bootstrap entry's reason in short, for a panel's title: each "; "-separated part up to its first
    ": " ("at its lower bound (consistent with 0)", "near its bound", "one end at the search range's end")."""
    return "; ".join(part.split(": ", 1)[0] for part in reason.split("; ") if part)
