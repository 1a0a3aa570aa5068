"""The figure next to a calibration's estimates: the bias with its band, and the normalized innovations."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def plot_calibration(
    time: np.ndarray,
    bias: np.ndarray,
    bias_std: np.ndarray,
    normalized_innovations: np.ndarray,
    path: str | Path,
    names: tuple[str, ...] = ("position", "velocity"),
) -> Path:
    """Bias estimate +- 1 and 2 sigma against time, and each normalized innovation with its +-3 band.

    Parameters
    ----------
    time : (K,) s; bias, bias_std : (K,) m/s^2; normalized_innovations : (K, p), dimensionless.
    """
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 6), sharex=True, constrained_layout=True)
    top.fill_between(time, bias - 2 * bias_std, bias + 2 * bias_std, color="tab:blue", alpha=0.15, label="±2σ")
    top.fill_between(time, bias - bias_std, bias + bias_std, color="tab:blue", alpha=0.3, label="±1σ")
    top.plot(time, bias, color="tab:blue", lw=1.2, label="bias estimate")
    top.set_ylabel("bias [m/s²]")
    top.set_title(f"accelerometer bias: {bias[-1]:.5g} ± {bias_std[-1]:.2g} m/s² at t = {time[-1]:g} s")
    top.legend(loc="upper right", fontsize="small")
    for component, name in enumerate(names):
        bottom.plot(time, normalized_innovations[:, component], ".", ms=2.5, label=name)
    for level in (-3, 3):
        bottom.axhline(level, color="k", ls="--", lw=0.8)
    bottom.set_ylabel("normalized innovation [σ]")
    bottom.set_xlabel("time [s]")
    bottom.legend(loc="upper right", fontsize="small", markerscale=3)
    path = Path(path)
    fig.savefig(path, dpi=100, metadata={"Software": None})
    plt.close(fig)
    return path
