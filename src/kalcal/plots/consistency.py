"""Figures beyond the source report: mean NEES and NIS, the residual correlation map, the model error.

Mean NEES and NIS with chi-square bounds, the residual correlation map over pairs of updates, and the
deterministic model-error response in units of the filter's sigma.

N realizations, K updates, d states, p measurements.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.colors import TwoSlopeNorm

from kalcal.plots._common import (
    BAND,
    ENSEMBLE,
    FILTER,
    STATE_COLORS,
    label,
    new_figure,
    percent,
    save,
    styled,
    time_label,
)
from kalcal.stats.bounds import COVARIANCE_PARTS, centered_nees_bounds, chi2_mean_bounds, whiteness_pairs_bound
from kalcal.stats.covariance import centered_nees

if TYPE_CHECKING:
    import xarray as xr

#: pixel height of the residual correlation map (its width is the common 900 px)
CORRELATION_HEIGHT_PX = 800


def _chi2_panel(ax, times, values, expected, low, high, band: str, what: str) -> None:
    """One mean chi-square statistic against time with its bounds band and expected value."""
    ax.axhspan(low, high, color=BAND, alpha=0.22, linewidth=0.0, label=band)
    ax.axhline(expected, color=FILTER, linestyle="--", linewidth=1.2, label=f"expected value {expected:g}")
    ax.plot(times, values, color=ENSEMBLE, linewidth=1.0, marker=".", markersize=3, label=what)
    ax.set_ylabel("dimensionless")
    ax.legend(loc="upper left")
    span = max(high - low, float(np.max(np.abs(values - expected))) * 2.0)
    ax.set_ylim(expected - 0.75 * span, expected + 0.75 * span)


def _mean_chi2(dataset: xr.Dataset, variable: str, dof: int, what: str, path) -> Path:
    times = dataset["time"].values
    count = int(dataset.attrs["realizations"])
    confidence = float(dataset.attrs["confidence"])
    values = dataset[variable].values
    low, high = chi2_mean_bounds(confidence, times.size, dof * count, count)
    figure, axes = new_figure(1)
    ax = axes[0, 0]
    band = f"χ²({dof}N)/N bounds, {percent(confidence)} over {times.size} updates"
    _chi2_panel(ax, times, values, dof, low, high, band, f"mean {what}")
    ax.set_xlabel(time_label())
    ax.set_ylabel(f"mean {what} (dimensionless)")
    ax.set_title(f"Mean {what} against time, N = {count:,} (bounds [{low:.4g}, {high:.4g}])")
    return save(figure, path)


def nees_band_label(confidence: float, n_updates: int, d: int) -> str:
    """The legend of the centered NEES band: the covariance check's NEES part, at its share of the
    check's alpha (:func:`~kalcal.stats.bounds.centered_nees_bounds`), e.g. 99.5% (alpha / 2) at 99%."""
    parts = len(COVARIANCE_PARTS)
    share = 1.0 - (1.0 - confidence) / parts
    return (
        f"covariance check's NEES part, χ²({d}(N−1))/(N−1), {percent(share)} (alpha / {parts}) "
        f"over {n_updates} updates"
    )


@styled
def plot_nees(dataset: xr.Dataset, path: str | Path) -> Path:
    """(a) The centered mean NEES, tr(P_k^-1 C_k) with C_k the ensemble covariance of e_k (divisor N - 1),
    the statistic the ``covariance`` check holds against chi-square(d (N - 1)) / (N - 1) bounds for K
    comparisons (:func:`~kalcal.stats.covariance.centered_nees`, the same bounds as the check); (b) the raw
    mean NEES, mean over realizations of e_k^T P_k^-1 e_k, with chi-square(N d) / N bounds: it uses the
    raw error, so a mean error lifts it, and no check tests it. 900 x 650 px.

    Parameters
    ----------
    dataset : xarray.Dataset
        A ``stats.nc`` Dataset (attributes ``realizations`` and ``confidence``).
    path : path of the PNG to write
    """
    times = dataset["time"].values
    count = int(dataset.attrs["realizations"])
    confidence = float(dataset.attrs["confidence"])
    d = dataset.sizes["state"]
    figure, axes = new_figure(2)
    if "whitened_second_moment" in dataset:  # each realization whitened by its own P_k: tr of W_k, as the check
        mean = dataset["mean_whitened_error"].values
        second = dataset["whitened_second_moment"].values - mean[:, :, None] * mean[:, None, :]
        centered = np.trace(second, axis1=1, axis2=2) * count / (count - 1)
    else:
        centered = centered_nees(dataset["error_cov"].values, dataset["filter_cov"].values)
    low, high = centered_nees_bounds(confidence, times.size, d, count)
    _chi2_panel(
        axes[0, 0],
        times,
        centered,
        d,
        low,
        high,
        nees_band_label(confidence, times.size, d),
        "centered mean NEES tr(P⁻¹ Cov e)",
    )
    axes[0, 0].set_title(
        f"(a) Centered mean NEES, the covariance check's statistic, N = {count:,} (bounds [{low:.4g}, {high:.4g}])"
    )
    raw_low, raw_high = chi2_mean_bounds(confidence, times.size, d * count, count)
    _chi2_panel(
        axes[1, 0],
        times,
        dataset["mean_nees"].values,
        d,
        raw_low,
        raw_high,
        f"χ²({d}N)/N bounds, {percent(confidence)} over {times.size} updates",
        "mean NEES eᵀP⁻¹e",
    )
    axes[1, 0].set_title("(b) Mean NEES of the raw error (a mean error lifts it; not a check)")
    axes[1, 0].set_xlabel(time_label())
    return save(figure, path)


@styled
def plot_nis(dataset: xr.Dataset, path: str | Path) -> Path:
    """Mean normalized innovation squared, mean of r_k^T S_k^-1 r_k, against time, with chi-square(N p) / N
    bounds for K comparisons (the ``nis`` check). 900 x 400 px.

    Parameters
    ----------
    dataset : xarray.Dataset
        A ``stats.nc`` Dataset (attributes ``realizations`` and ``confidence``).
    path : path of the PNG to write
    """
    return _mean_chi2(dataset, "mean_nis", dataset.sizes["measurement"], "NIS", path)


@styled
def plot_residual_correlation(dataset: xr.Dataset, path: str | Path) -> Path:
    """Heat maps of the residual correlation rho_ab(k, j) = E[r_k,a r_j,b] / sqrt(E[r_k,a^2] E[r_j,b^2]).

    One panel per measurement pair (a, b), time t_k up and t_j across; the diagonal k = j (where the
    correlation is not required to vanish) is masked grey. White innovations give noise of standard
    error 1 / sqrt(N); the colour scale is symmetric and reaches at least the whiteness check's bound
    z / sqrt(N) (its pairs part's: z for p^2 K (K - 1) / 2 comparisons at alpha / 2), so a pale map passes
    the pairs part and saturated structure fails it (a faint pattern over many pairs is the portmanteau's to
    find).

    900 x 800 px.

    Parameters
    ----------
    dataset : xarray.Dataset
        With ``residual_second_moment`` (K, p, K, p), E[r_k r_j^T] over all pairs of updates.
    path : path of the PNG to write
    """
    times = dataset["time"].values
    count = int(dataset.attrs["realizations"])
    confidence = float(dataset.attrs["confidence"])
    names = [str(v) for v in dataset["measurement"].values]
    moment = dataset["residual_second_moment"].values
    n_updates, p = moment.shape[:2]
    power = np.diagonal(moment.reshape(n_updates * p, n_updates * p)).reshape(n_updates, p)
    scale = np.sqrt(np.einsum("ka,jb->kajb", power, power))
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = np.where(scale > 0, moment / np.where(scale > 0, scale, 1.0), 0.0)
    rho[np.arange(n_updates), :, np.arange(n_updates), :] = np.nan
    bound = whiteness_pairs_bound(confidence, n_updates, p) / np.sqrt(count)
    finite = np.abs(rho[np.isfinite(rho)])
    vmax = max(bound, float(finite.max()) if finite.size else bound)
    norm = TwoSlopeNorm(vcenter=0.0, vmin=-vmax, vmax=vmax)
    figure, axes = new_figure(p, p, height=CORRELATION_HEIGHT_PX, sharex=True)
    # one update (a batch estimator's final time) has no spacing: its cell is one unit wide, not zero
    step = (times[-1] - times[0]) / (n_updates - 1) if n_updates > 1 else 1.0
    extent = (times[0] - step / 2, times[-1] + step / 2, times[0] - step / 2, times[-1] + step / 2)
    image = None
    for a in range(p):
        for b in range(p):
            ax = axes[a, b]
            ax.grid(False)
            image = ax.imshow(rho[:, a, :, b], origin="lower", extent=extent, cmap=_correlation_cmap(), norm=norm, interpolation="nearest", aspect="auto")
            ax.set_title(f"r_{names[a]}(t_k) with r_{names[b]}(t_j)")
            ax.set_ylabel(label("t_k", "s"))
            ax.set_xlabel(label("t_j", "s"))
    figure.suptitle(f"Residual correlation over pairs of updates, N = {count:,}; whiteness bound ±{bound:.3g} (black ticks)")
    colorbar = figure.colorbar(image, ax=list(figure.axes), shrink=0.9, label="correlation (dimensionless)")
    colorbar.ax.axhline(bound, color="black", linewidth=1.0)
    colorbar.ax.axhline(-bound, color="black", linewidth=1.0)
    return save(figure, path)


def _correlation_cmap():
    from matplotlib import colormaps

    return colormaps["RdBu_r"].with_extremes(bad="0.8")


@styled
def plot_model_error(dataset: xr.Dataset, path: str | Path) -> Path:
    """Deterministic model-error response: expected_mean_error_i(t) / sqrt(P_ii(t)), per state.

    What the truth's departure from the filter's model (the integration scheme, a prior-mean offset)
    does to the mean error, with no noise, in units of the filter's own sigma; the measured ensemble
    mean error in the same units is drawn as dots for comparison. Values near 1 mean the filter's 1 sigma
    bounds are off-centre by a whole sigma. 900 x 400 px.

    Parameters
    ----------
    dataset : xarray.Dataset
        A ``stats.nc`` Dataset: ``expected_mean_error`` and ``mean_error`` (K, d), ``filter_cov`` (K, d, d).
    path : path of the PNG to write
    """
    times = dataset["time"].values
    names = [str(v) for v in dataset["state"].values]
    sigma = np.sqrt(np.diagonal(dataset["filter_cov"].values, axis1=1, axis2=2))
    with np.errstate(divide="ignore", invalid="ignore"):
        expected = np.where(sigma > 0, dataset["expected_mean_error"].values / np.where(sigma > 0, sigma, 1.0), 0.0)
        measured = np.where(sigma > 0, dataset["mean_error"].values / np.where(sigma > 0, sigma, 1.0), 0.0)
    figure, axes = new_figure(1)
    ax = axes[0, 0]
    for i, name in enumerate(names):
        color = STATE_COLORS[i % len(STATE_COLORS)]
        ax.plot(times, expected[:, i], color=color, linewidth=1.6, label=f"{name}: expected (model error)")
        ax.plot(times, measured[:, i], color=color, linestyle="none", marker=".", markersize=3.5, alpha=0.7, label=f"{name}: ensemble mean")
    ax.axhline(0.0, color="grey", linewidth=0.6)
    ax.set_xlabel(time_label())
    ax.set_ylabel("mean error / filter σ (σ)")
    ax.legend(loc="best", ncols=2)
    ax.set_title(f"Deterministic model-error response in units of the filter's σ (largest {np.max(np.abs(expected)):.2f} σ)")
    return save(figure, path)
