"""The figure next to a calibration's estimates: the bias with its band, and the normalized innovations."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from kalcal.plots._common import ESTIMATE, label, new_figure, save, shade_band, styled, time_label


@styled
def plot_calibration(
    time: np.ndarray,
    bias: np.ndarray,
    bias_std: np.ndarray,
    normalized_innovations: np.ndarray,
    path: str | Path,
    names: tuple[str, ...] = ("position", "velocity"),
    note: str = "",
) -> Path:
    """Bias estimate +- 1 and 2 sigma against time, and each normalized innovation with its +-3 band.

    900 x 650 px.

    Parameters
    ----------
    time : (K,) s; bias, bias_std : (K,) m/s^2; normalized_innovations : (K, p), dimensionless.
    note : str
        A second title line that must stand beside the sigma (it is not trusted, or its value over the
        noise settings the log cannot reject); "" for none.
    """
    figure, axes = new_figure(2)
    top, bottom = axes[0, 0], axes[1, 0]
    shade_band(top, time, bias - 2 * bias_std, bias + 2 * bias_std, "±2σ", ESTIMATE)
    shade_band(top, time, bias - bias_std, bias + bias_std, "±1σ", ESTIMATE)
    top.plot(time, bias, color=ESTIMATE, linewidth=1.2, label="bias estimate")
    top.set_ylabel(label("bias", "m/s²"))
    title = f"accelerometer bias: {bias[-1]:.5g} ± {bias_std[-1]:.2g} m/s² at t = {time[-1]:g} s"
    untrusted = note.startswith("sigma NOT trusted")
    top.set_title(title + (f"\n{note}" if note else ""), **({"color": "firebrick"} if untrusted else {}))
    top.legend(loc="upper right")
    for component, name in enumerate(names):
        bottom.plot(time, normalized_innovations[:, component], ".", markersize=2.5, label=name)
    for level in (-3, 3):
        bottom.axhline(level, color="black", linestyle="--", linewidth=0.8)
    bottom.set_ylabel(label("normalized innovation", "σ"))
    bottom.set_xlabel(time_label())
    bottom.legend(loc="upper right", markerscale=3)
    return save(figure, path)
