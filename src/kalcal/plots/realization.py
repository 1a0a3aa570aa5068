"""Figures of one realization: the true error state against the estimate, the error against +-1 sigma.

The estimation error is drawn against the filter's own +-1 sigma (source report, figures 5.1-5.6).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from kalcal.plots.realization_data import RealizationData  # noqa: F401 (re-exported: its old home)
from kalcal.plots._common import (
    ESTIMATE,
    SIGMA,
    TRUTH,
    label,
    new_figure,
    save,
    shade_band,
    styled,
    time_label,
)


@styled
def plot_state_estimate(data: RealizationData, state: int, path: str | Path) -> Path:
    """True state x_i and the filter's estimate xhat_i +- 1 sigma against time (report 5.1-5.3).

    900 x 400 px.

    Parameters
    ----------
    data : RealizationData
    state : int
        Index i of the state to draw.
    path : path of the PNG to write
    """
    name, unit, symbol = data.state_names[state], data.state_units[state], data.state_label(state)
    sigma = data.sigma(state)
    figure, axes = new_figure(1)
    ax = axes[0, 0]
    estimate = data.estimate[:, state]
    shade_band(ax, data.times, estimate - sigma, estimate + sigma, "estimate ± 1σ (filter P)", SIGMA)
    ax.plot(data.times, data.truth[:, state], color=TRUTH, linewidth=1.4, label=f"true {symbol}")
    ax.plot(data.times, estimate, color=ESTIMATE, linewidth=1.1, linestyle="--", marker=".", markersize=3, label=f"estimated {symbol.partition(' = ')[0]}")
    ax.set_xlabel(time_label())
    ax.set_ylabel(label(f"{name} state" if symbol == name else symbol, unit))
    what = f"{name.capitalize()} state" + ("" if symbol == name else f" {symbol}")
    ax.set_title(f"{what}: true and estimated, realization {data.index}")
    ax.legend(loc="best")
    return save(figure, path)


def _error_panel(ax, data: RealizationData, state: int, times_mask=None) -> None:
    name, unit = data.state_names[state], data.state_units[state]
    mask = np.ones(data.times.shape, dtype=bool) if times_mask is None else times_mask
    times, error, sigma = data.times[mask], data.error[mask, state], data.sigma(state)[mask]
    shade_band(ax, times, -sigma, sigma, "± 1σ from the filter's P", SIGMA)
    ax.plot(times, error, color=TRUTH, linewidth=1.0, marker=".", markersize=3, label=f"{name} error e = x - x̂")
    ax.axhline(0.0, color="grey", linewidth=0.6)
    ax.set_ylabel(label(f"{name} error", unit))
    ax.legend(loc="upper right")


@styled
def plot_estimation_error(data: RealizationData, state: int, path: str | Path) -> Path:
    """Estimation error e_i = x_i - xhat_i with the filter's +-sqrt(P_ii) band (report 5.4, 5.5).

    900 x 400 px.

    Parameters
    ----------
    data : RealizationData
    state : int
        Index i of the state to draw.
    path : path of the PNG to write
    """
    figure, axes = new_figure(1)
    ax = axes[0, 0]
    _error_panel(ax, data, state)
    ax.set_xlabel(time_label())
    ax.set_title(f"Estimation error of {data.state_names[state]}, realization {data.index}")
    return save(figure, path)


def magnified_window(times: np.ndarray) -> np.ndarray:
    """The part of the run shown magnified: its last two thirds, where the bounds have settled, (K,) bool."""
    start = times[0] + (times[-1] - times[0]) / 3.0
    return times >= start


@styled
def plot_estimation_error_magnified(data: RealizationData, state: int, path: str | Path) -> Path:
    """Estimation error with +-1 sigma over the whole run (a) and magnified over its last two thirds (b)
    (report 5.6: the bias bounds shrink towards zero, so the magnified view shows they still hold).

    900 x 650 px.

    Parameters
    ----------
    data : RealizationData
    state : int
        Index i of the state to draw.
    path : path of the PNG to write
    """
    figure, axes = new_figure(2, sharex=False)
    name = data.state_names[state]
    _error_panel(axes[0, 0], data, state)
    axes[0, 0].set_title(f"(a) Estimation error of {name}, realization {data.index}")
    window = magnified_window(data.times)
    _error_panel(axes[1, 0], data, state, window)
    reach = max(float(np.max(data.sigma(state)[window])), float(np.max(np.abs(data.error[window, state]))))
    axes[1, 0].set_ylim(-1.25 * reach, 1.25 * reach)
    axes[1, 0].set_title(f"(b) Magnified: t ≥ {data.times[window][0]:g} s")
    axes[1, 0].set_xlabel(time_label())
    axes[0, 0].set_xlabel(time_label())
    return save(figure, path)
