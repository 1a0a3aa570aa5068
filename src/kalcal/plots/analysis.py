"""Figures of the exact covariance analysis (``analysis.nc``): filter against true sigma, and the error budget."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from kalcal.plots._common import ENSEMBLE, FILTER, STATE_COLORS, label, new_figure, save, styled, time_label

if TYPE_CHECKING:  # type hints only
    import xarray as xr


#: colours of the budget's sources by kind, light to dark within a kind
_KIND_COLORS = {
    "prior": ("#c6dbef", "#6baed6", "#2171b5", "#08306b"),
    "process": ("#fdd0a2", "#fd8d3c", "#d94801", "#7f2704"),
    "measurement": ("#c7e9c0", "#74c476", "#238b45", "#00441b"),
}


def plot_analysis(dataset: xr.Dataset, figure_dir: str | Path) -> dict[str, Path]:
    """Both figures of ``analysis.nc`` (a Dataset or its parts) into ``figure_dir``, by key: ``sigma``
    (``sigma.png``, :func:`plot_sigma`) and ``budget`` (``budget.png``, :func:`plot_budget`)."""
    figure_dir = Path(figure_dir)
    return {"sigma": plot_sigma(dataset, figure_dir / "sigma.png"), "budget": plot_budget(dataset, figure_dir / "budget.png")}


@styled
def plot_sigma(dataset: xr.Dataset, path: str | Path) -> Path:
    """The filter's sigma sqrt(P_ii) (dashed) against the true sigma sqrt(P_true,ii) (solid), one panel per state.

    Also sqrt(E[e_i^2]) (dotted) where the mean error adds to the spread. 900 x (150 + 250 d) px.
    """
    times = dataset["time"].values
    names = [str(s) for s in dataset["state"].values]
    units = [str(u) for u in dataset["state_unit"].values]
    figure, axes = new_figure(len(names))
    raw = np.sqrt(dataset["true_sigma"].values ** 2 + dataset["mean_error"].values ** 2)
    for i, (name, unit) in enumerate(zip(names, units)):
        ax = axes[i, 0]
        color = STATE_COLORS[i % len(STATE_COLORS)]
        ax.plot(times, dataset["true_sigma"].values[:, i], color=color, linewidth=1.3, label=f"true σ of {name} (√P_true)")
        ax.plot(times, dataset["filter_sigma"].values[:, i], color=FILTER, linestyle="--", linewidth=1.1, label="filter σ (√P)")
        if np.any(np.abs(dataset["mean_error"].values[:, i]) > 1e-3 * dataset["true_sigma"].values[:, i]):
            ax.plot(times, raw[:, i], color=ENSEMBLE, linestyle=":", linewidth=1.1, label="√E[e²] (with the mean error)")
        if np.all(dataset["true_sigma"].values[:, i] > 0):
            ax.set_yscale("log")
        ax.set_ylabel(label(f"σ of {name}", unit))
        ax.legend(loc="upper right")
    axes[-1, 0].set_xlabel(time_label())
    axes[0, 0].set_title("Filter σ against the true σ of its error (exact covariance analysis)")
    return save(figure, path)


def _colors(kinds: list[str]) -> list[str]:
    seen: dict[str, int] = {}
    out = []
    for kind in kinds:
        palette = _KIND_COLORS.get(kind, ("#bdbdbd", "#737373", "#252525"))
        out.append(palette[seen.get(kind, 0) % len(palette)])
        seen[kind] = seen.get(kind, 0) + 1
    return out


@styled
def plot_budget(dataset: xr.Dataset, path: str | Path) -> Path:
    """Each source's share of each state's true error variance over time, stacked to 1, one panel per state.

    The shares are the diagonal of each budget term over the diagonal of P_true; the legend names the
    sources (prior, process and measurement in blues, oranges and greens). 900 x (150 + 250 d) px.
    """
    times = dataset["time"].values
    names = [str(s) for s in dataset["state"].values]
    sources = [str(s) for s in dataset["source"].values]
    colors = _colors([str(k) for k in dataset["kind"].values])
    terms = np.clip(np.diagonal(dataset["budget"].values, axis1=-2, axis2=-1), 0.0, None)  # (S, K, d)
    total = terms.sum(axis=0)
    shares = np.divide(terms, total, out=np.zeros_like(terms), where=total > 0)
    figure, axes = new_figure(len(names))
    for i, name in enumerate(names):
        ax = axes[i, 0]
        ax.stackplot(times, shares[:, :, i], colors=colors, labels=sources, linewidth=0.0)
        ax.set_ylim(0.0, 1.0)
        ax.set_xlim(times[0], times[-1])
        ax.set_ylabel(f"share of var({name})")
    axes[0, 0].legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8.0)
    axes[-1, 0].set_xlabel(time_label())
    axes[0, 0].set_title("Error budget: each source's share of the true error variance")
    return save(figure, path)
