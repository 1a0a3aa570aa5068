"""The time-varying filter variances against the steady state of the Riccati equation (DARE)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from kalcal.plots._common import FILTER, STATE_COLORS, label, new_figure, save, styled, time_label, unit_square


@styled
def plot_steady_state(
    times: np.ndarray,
    posterior_diag: np.ndarray,
    steady_diag: np.ndarray,
    state_names: tuple[str, ...],
    state_units: tuple[str, ...],
    path: str | Path,
    *,
    stabilizing: bool = True,
    converged_time: float | None = None,
) -> Path:
    """P_k,ii of the time-varying filter (solid) and P_inf,ii (dashed), one panel per state, log scale.

    Parameters
    ----------
    times : ndarray, shape (K,)
        Update times, s.
    posterior_diag : ndarray, shape (K, d)
        Diagonal of P_k.
    steady_diag : ndarray, shape (d,)
        Diagonal of P_inf (a zero is not drawn on the log scale).
    stabilizing : bool
        Whether P_inf is the stabilizing solution (the label says so when it is not).
    converged_time : float, optional
        Where ||P_k - P_inf|| / ||P_inf|| stays below the tolerance, marked with a dotted line.

    900 x (150 + 250 d) px.
    """
    d = len(state_names)
    figure, axes = new_figure(d)
    steady_label = "P∞ (DARE)" if stabilizing else "DARE solution (not stabilizing)"
    for i, (name, unit) in enumerate(zip(state_names, state_units)):
        ax = axes[i, 0]
        color = STATE_COLORS[i % len(STATE_COLORS)]
        ax.plot(times, posterior_diag[:, i], color=color, linewidth=1.2, label=f"P_k of {name} (time-varying)")
        if steady_diag[i] > 0:
            ax.axhline(steady_diag[i], color=FILTER, linestyle="--", linewidth=1.1, label=steady_label)
        if converged_time is not None:
            ax.axvline(converged_time, color=FILTER, linestyle=":", linewidth=1.0, label="converged (1e-3)")
        positive = posterior_diag[:, i][posterior_diag[:, i] > 0]
        if positive.size:
            ax.set_yscale("log")
        ax.set_ylabel(label(f"variance of {name}", unit_square(unit)))
        ax.legend(loc="upper right")
    axes[-1, 0].set_xlabel(time_label())
    axes[0, 0].set_title("Filter variance P_k against the steady state P∞ of the Riccati equation")
    return save(figure, path)
