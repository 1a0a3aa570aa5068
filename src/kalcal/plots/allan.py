"""The Allan deviation of a static accelerometer log with its confidence band and the slopes read off it."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from kalcal.calibration.noise import BIAS_INSTABILITY_FACTOR, NoiseIdentification
from kalcal.plots._common import height_px, label, new_figure, percent, save, shade_band, styled

#: colours of the three read-off lines
LINE_COLORS = {"white": "tab:blue", "flat": "tab:green", "rate_random_walk": "tab:red"}


@styled
def plot_allan(result: NoiseIdentification, path: str | Path, title: str = "") -> Path:
    """Log-log sigma(tau) with its confidence band, and each identified line.

    The lines are N / sqrt(tau) (slope -1/2), 0.664 B (flat) and K sqrt(tau / 3) (slope +1/2), drawn thin
    over the whole tau range and thick over the region they were read from. 900 x 550 px.

    Parameters
    ----------
    result : the identification; tau in s, sigma in m/s^2.
    """
    curve = result.curve
    figure, axes = new_figure(1, 1, height=height_px(1) + 150)
    ax = axes[0, 0]
    tau = curve.tau
    shade_band(ax, tau, curve.low, curve.high, f"{percent(curve.confidence)} confidence", color="0.6")
    ax.plot(tau, curve.adev, "o-", color="black", ms=4, lw=1.2, label="overlapping Allan deviation")
    grid = np.geomspace(tau[0], tau[-1], 200)
    lines = []
    vrw, bias, rrw = result.velocity_random_walk, result.bias_instability, result.rate_random_walk
    if vrw.identified:
        lines.append(
            ("white", lambda t: vrw.value / np.sqrt(t), vrw.tau_range,
             f"N = {vrw.value:.3g} m/s/√s (slope −1/2; accel_noise_std {result.accel_noise_std.value:.3g} m/s²)")
        )
    if bias.identified:
        lines.append(
            ("flat", lambda t: np.full_like(t, BIAS_INSTABILITY_FACTOR * bias.value), bias.tau_range,
             f"B = {bias.value:.3g} m/s² (flat at 0.664 B)")
        )
    if rrw.identified:
        lines.append(
            ("rate_random_walk", lambda t: rrw.value * np.sqrt(t / 3.0), rrw.tau_range,
             f"K = {rrw.value:.3g} m/s²/√s (slope +1/2)")
        )
    for name, line, (first, last), text in lines:
        color = LINE_COLORS[name]
        ax.plot(grid, line(grid), "--", color=color, lw=1.0)
        region = np.geomspace(first, last, 50) if last > first else np.array([first / 1.3, first * 1.3])
        ax.plot(region, line(region), "-", color=color, lw=3.0, alpha=0.7, label=text)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(label("averaging time τ", "s"))
    ax.set_ylabel(label("Allan deviation σ(τ)", "m/s²"))
    missing = [p.name for p in (vrw, bias, rrw) if not p.identified]
    subtitle = f"{result.samples:,} samples at {result.rate:.6g} Hz, {result.duration:.6g} s"
    if missing:
        subtitle += "; not on the curve: " + ", ".join(name.replace("_", " ") for name in missing)
    ax.set_title(f"{title}\n{subtitle}" if title else subtitle)
    ax.legend(loc="best")
    return save(figure, path)


#: colours of a three-axis log's curves
AXIS_COLORS = {"x": "tab:blue", "y": "tab:green", "z": "tab:red"}


@styled
def plot_allan_axes(axes_results: dict[str, NoiseIdentification], path: str | Path, title: str = "",
                    selected: str | None = None) -> Path:
    """Log-log sigma(tau) of each axis of a three-axis log, with its confidence band; the legend gives
    each axis's N, B and K (the read-off lines of one axis are :func:`plot_allan`'s). 900 x 550 px.

    Parameters
    ----------
    axes_results : ``{axis: identification}``; tau in s, sigma in m/s^2.
    selected : the axis ``--axis`` selected (drawn thicker), if any.
    """
    figure, axes = new_figure(1, 1, height=height_px(1) + 150)
    ax = axes[0, 0]
    first = next(iter(axes_results.values()))
    for name, result in axes_results.items():
        curve = result.curve
        color = AXIS_COLORS.get(name, None)
        shade_band(ax, curve.tau, curve.low, curve.high, None, color=color)
        values = [
            f"{symbol} = {p.value:.3g}" if p.identified else f"{symbol} not seen"
            for symbol, p in (("N", result.velocity_random_walk), ("B", result.bias_instability),
                              ("K", result.rate_random_walk))
        ]
        ax.plot(curve.tau, curve.adev, "o-", color=color, ms=3, lw=2.2 if name == selected else 1.2,
                label=f"axis {name}: " + ", ".join(values) + (" (selected)" if name == selected else ""))
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(label("averaging time τ", "s"))
    ax.set_ylabel(label("Allan deviation σ(τ)", "m/s²"))
    subtitle = (f"{first.samples:,} samples at {first.rate:.6g} Hz, {first.duration:.6g} s; "
                f"bands: {percent(first.curve.confidence)} confidence; N m/s/√s, B m/s², K m/s²/√s")
    ax.set_title(f"{title}\n{subtitle}" if title else subtitle)
    ax.legend(loc="best")
    return save(figure, path)
