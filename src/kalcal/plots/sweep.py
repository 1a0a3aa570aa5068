"""The tuning curve of a sweep: each check's statistic against the swept setting."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402


def plot_sweep(table: pd.DataFrame, key: str, path: str | Path) -> Path:
    """One panel per check: the statistic (dots; red where it failed) and its bounds against ``key``.

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
    fig, axes = plt.subplots(1, len(checks), figsize=(3.2 * len(checks), 3.2), constrained_layout=True)
    for ax, check in zip(np.atleast_1d(axes), checks):
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
    np.atleast_1d(axes)[0].set_ylabel("statistic")
    np.atleast_1d(axes)[0].legend(fontsize="small")
    path = Path(path)
    fig.savefig(path, dpi=100, metadata={"Software": None})
    plt.close(fig)
    return path
