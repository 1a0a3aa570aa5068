"""The tuning curve of a sweep: each check's statistic against the swept setting."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from kalcal.plots._common import new_figure, save, styled


@styled
def plot_sweep(table: pd.DataFrame, key: str, path: str | Path) -> Path:
    """One panel per check: the statistic (dots; red where it failed) and its bounds against ``key``.

    900 x 400 px.

    Parameters
    ----------
    table : DataFrame
        ``sweep.csv``: the column ``key`` and, per check, ``<check>_statistic``, ``_lower``, ``_upper``,
        ``_passed``.
    """
    checks = [c[: -len("_statistic")] for c in table.columns if c.endswith("_statistic")]
    x = table[key].to_numpy()
    numeric = np.issubdtype(np.asarray(x).dtype, np.number)
    positions = x if numeric else np.arange(len(x))
    figure, axes = new_figure(1, len(checks), sharex=False)
    axes = axes[0]
    for ax, check in zip(axes, checks):
        stat = table[f"{check}_statistic"].to_numpy(dtype=float)
        passed = table[f"{check}_passed"].to_numpy(dtype=bool)
        upper = table[f"{check}_upper"].to_numpy(dtype=float)
        lower = pd.to_numeric(table[f"{check}_lower"], errors="coerce").to_numpy(dtype=float)
        ax.plot(positions, stat, color="0.4", lw=1)
        ax.scatter(positions[passed], stat[passed], color="tab:green", zorder=3, label="pass")
        ax.scatter(positions[~passed], stat[~passed], color="tab:red", zorder=3, label="fail")
        ax.plot(positions, upper, "k--", lw=1, label="bound")
        if np.any(np.isfinite(lower)):
            ax.plot(positions, lower, "k--", lw=1)
        ax.set_title(check)
        ax.set_xlabel(key)
        if numeric and np.all(x > 0) and x.max() / x.min() > 5:
            ax.set_xscale("log")
            ax.minorticks_off()
        ax.set_xticks(positions, [f"{v:g}" if numeric else str(v) for v in x])
        if np.all(stat > 0) and stat.max() / max(stat.min(), 1e-300) > 50:
            ax.set_yscale("log")
    axes[0].set_ylabel("statistic")
    axes[0].legend()
    return save(figure, path)
