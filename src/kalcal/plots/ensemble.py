"""Figures of the ensemble statistics in ``stats.nc``: mean error, covariance and orthogonality in time.

Each has the band a correct filter stays in (source report, figures 5.7-5.12).

Every band is the one the matching check in :mod:`kalcal.stats.suite` holds the statistic to: the
standard error of the statistic times the Bonferroni-corrected normal quantile for the family of all
updates and elements, at the run's confidence (``dataset.attrs["confidence"]``). N realizations, K
updates, d states.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from kalcal.plots._common import (
    BAND,
    ENSEMBLE,
    EXPECTED,
    FILTER,
    label,
    legend_below,
    new_figure,
    percent,
    save,
    shade_band,
    styled,
    time_label,
    unit_product,
    unit_square,
)
from kalcal.stats.bounds import covariance_element_bound, normal_bound
from kalcal.stats.self_check import compared_states, variance_ratio_band

if TYPE_CHECKING:
    import xarray as xr


def _names(dataset: xr.Dataset) -> tuple[list[str], list[str]]:
    return [str(v) for v in dataset["state"].values], [str(v) for v in dataset["state_unit"].values]


def _run(dataset: xr.Dataset) -> tuple[np.ndarray, int, float]:
    """Update times (s), realizations N and confidence of a stats Dataset."""
    return dataset["time"].values, int(dataset.attrs["realizations"]), float(dataset.attrs["confidence"])


@styled
def plot_mean_error(dataset: xr.Dataset, path: str | Path, *, title: str | None = None) -> Path:
    """Ensemble mean error e_ave,i(t) of each state with its confidence band and the expected mean error.

    The band is +- z sqrt(C_ii / N) about zero, C the ensemble covariance of e and z the two-sided normal
    quantile at the run's confidence for K d comparisons (the ``mean_error`` check). The dashed curve is
    ``expected_mean_error``, the mean error that deterministic model error (and prior-mean offsets) alone
    produce. Report figures 5.7 and, for a longer run, 5.8.

    900 x (150 + 250 d) px.

    Parameters
    ----------
    dataset : xarray.Dataset
        A ``stats.nc`` Dataset: ``mean_error`` (K, d), ``expected_mean_error`` (K, d), ``error_cov``
        (K, d, d), attributes ``realizations`` and ``confidence``.
    path : path of the PNG to write
    title : str, optional
        Figure title (default names the horizon and N).
    """
    times, count, confidence = _run(dataset)
    names, units = _names(dataset)
    mean = dataset["mean_error"].values
    expected = dataset["expected_mean_error"].values
    variance = np.diagonal(dataset["error_cov"].values, axis1=1, axis2=2)
    z = normal_bound(confidence, mean.size)
    half = z * np.sqrt(variance / count)
    figure, axes = new_figure(len(names))
    for i, (name, unit) in enumerate(zip(names, units)):
        ax = axes[i, 0]
        shade_band(ax, times, -half[:, i], half[:, i], f"±{z:.2f} standard errors ({percent(confidence)}, Bonferroni)")
        ax.plot(times, mean[:, i], color=ENSEMBLE, linewidth=1.2, label="ensemble mean error")
        ax.plot(times, expected[:, i], color=EXPECTED, linestyle="--", linewidth=1.4, label="expected (deterministic model error)")
        ax.axhline(0.0, color="grey", linewidth=0.6)
        ax.set_ylabel(label(f"mean {name} error", unit))
    axes[-1, 0].set_xlabel(time_label())
    figure.suptitle(title or f"Ensemble mean error over [0, {times[-1]:g}] s, N = {count:,}")
    legend_below(figure, axes[:1, 0], ncols=3)
    return save(figure, path)


@styled
def plot_variance_diagonal(dataset: xr.Dataset, path: str | Path) -> Path:
    """Ensemble variance C_ii(t) against the filter's variance P_ii(t) (report 5.9).

    Left column: both on a log scale. Right column: the ratio C_ii / P_ii with the band
    1 +- z sqrt(2 / N) (a variance estimated from N Gaussian samples has standard deviation
    P_ii sqrt(2 / N)); z is the bound of the ``covariance`` check's element-wise part (the normal quantile
    for K d (d + 1) / 2 comparisons at half its alpha). A ratio above the band means an overconfident filter, below it an underconfident one.

    d rows of two panels: 900 x (150 + 250 d) px.

    Parameters
    ----------
    dataset : xarray.Dataset
        A ``stats.nc`` Dataset: ``error_cov`` and ``filter_cov`` (K, d, d), attributes ``realizations``
        and ``confidence``.
    path : path of the PNG to write
    """
    times, count, confidence = _run(dataset)
    names, units = _names(dataset)
    d = len(names)
    ensemble = np.diagonal(dataset["error_cov"].values, axis1=1, axis2=2)
    filt = np.diagonal(dataset["filter_cov"].values, axis1=1, axis2=2)
    z = covariance_element_bound(confidence, times.size, d)
    half = z * np.sqrt(2.0 / count)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(filt > 0, ensemble / np.where(filt > 0, filt, 1.0), np.nan)
    figure, axes = new_figure(d, 2)
    for i, (name, unit) in enumerate(zip(names, units)):
        ax = axes[i, 0]
        ax.plot(times, filt[:, i], color=FILTER, linestyle="--", linewidth=1.4, label="filter P_ii")
        ax.plot(times, ensemble[:, i], color=ENSEMBLE, linewidth=1.0, label="ensemble variance")
        ax.set_yscale("log")
        ax.set_ylabel(label(f"{name} variance", unit_square(unit)))
        ax = axes[i, 1]
        shade_band(ax, times, np.full(times.shape, 1.0 - half), np.full(times.shape, 1.0 + half), f"1 ± {z:.2f} sd")
        ax.axhline(1.0, color=FILTER, linestyle="--", linewidth=1.0)
        ax.plot(times, ratio[:, i], color=ENSEMBLE, linewidth=1.0, label="ensemble / filter")
        ax.set_ylabel(f"{name} variance ratio")
    for c in range(2):
        axes[-1, c].set_xlabel(time_label())
    legend_below(figure, axes[0])
    figure.suptitle(f"Error variance: ensemble (N = {count:,}) against the filter's P, diagonal terms")
    return save(figure, path)


@styled
def plot_variance_offdiagonal(dataset: xr.Dataset, path: str | Path) -> Path:
    """Ensemble covariance C_il(t) against the filter's P_il(t) for every pair i < l (report 5.10).

    Left column: the covariances as correlation coefficients, C_il / sqrt(C_ii C_ll) and
    P_il / sqrt(P_ii P_ll) (dimensionless, so the early transient and the settled values share one
    linear axis). Right column: the deviation (C_il - P_il) / sd_il in standard deviations,
    sd_il^2 = (P_il^2 + P_ii P_ll) / N, with the band +- z of the ``covariance`` check's element-wise
    part (z for K d (d + 1) / 2 comparisons at half its alpha).

    d (d - 1) / 2 rows of two panels: 900 x (150 + 250 d (d - 1) / 2) px.

    Parameters
    ----------
    dataset : xarray.Dataset
        A ``stats.nc`` Dataset (attributes ``realizations`` and ``confidence``).
    path : path of the PNG to write
    """
    times, count, confidence = _run(dataset)
    names, _ = _names(dataset)
    d = len(names)
    ensemble = dataset["error_cov"].values
    filt = dataset["filter_cov"].values
    pairs = [(i, l) for i in range(d) for l in range(i + 1, d)]
    z = covariance_element_bound(confidence, times.size, d)
    figure, axes = new_figure(max(1, len(pairs)), 2)
    for row, (i, l) in enumerate(pairs):
        with np.errstate(divide="ignore", invalid="ignore"):
            rho_filter = filt[:, i, l] / np.sqrt(filt[:, i, i] * filt[:, l, l])
            rho_ensemble = ensemble[:, i, l] / np.sqrt(ensemble[:, i, i] * ensemble[:, l, l])
            sd = np.sqrt((filt[:, i, l] ** 2 + filt[:, i, i] * filt[:, l, l]) / count)
            deviation = np.where(sd > 0, (ensemble[:, i, l] - filt[:, i, l]) / np.where(sd > 0, sd, 1.0), np.nan)
        ax = axes[row, 0]
        ax.plot(times, rho_filter, color=FILTER, linestyle="--", linewidth=1.4, label="filter P")
        ax.plot(times, rho_ensemble, color=ENSEMBLE, linewidth=1.0, label="ensemble")
        ax.set_ylim(-1.05, 1.05)
        ax.set_ylabel(f"corr({names[i]}, {names[l]})")
        ax = axes[row, 1]
        shade_band(ax, times, np.full(times.shape, -z), np.full(times.shape, z), f"±{z:.2f} sd ({percent(confidence)}, Bonferroni)")
        ax.plot(times, deviation, color=ENSEMBLE, linewidth=1.0, label="(ensemble - filter) / sd")
        ax.axhline(0.0, color="grey", linewidth=0.6)
        reach = max(1.3 * z, float(np.nanmax(np.abs(deviation))) * 1.1 if np.any(np.isfinite(deviation)) else z)
        ax.set_ylim(-reach, reach)
        ax.set_ylabel(f"cov({names[i]}, {names[l]}) deviation (sd)")
    for c in range(2):
        axes[-1, c].set_xlabel(time_label())
    legend_below(figure, axes[0])
    figure.suptitle(f"Error covariance: ensemble (N = {count:,}) against the filter's P, off-diagonal terms")
    return save(figure, path)


def _orthogonality(dataset: xr.Dataset, cells: list[tuple[int, int]], cols: int, path, title: str) -> Path:
    times, count, confidence = _run(dataset)
    names, units = _names(dataset)
    d = len(names)
    moment = dataset["error_estimate"].values
    e2 = np.diagonal(dataset["error_second_moment"].values, axis1=1, axis2=2)
    x2 = np.diagonal(dataset["estimate_second_moment"].values, axis1=1, axis2=2)
    z = normal_bound(confidence, times.size * d * d)
    rows = -(-len(cells) // cols)
    figure, axes = new_figure(rows, cols)
    for n, (i, l) in enumerate(cells):
        ax = axes[n // cols, n % cols]
        half = z * np.sqrt(e2[:, i] * x2[:, l] / count)
        shade_band(ax, times, -half, half, f"±{z:.2f} standard errors")
        ax.plot(times, moment[:, i, l], color=ENSEMBLE, linewidth=1.0, label="ensemble")
        ax.axhline(0.0, color="grey", linewidth=0.6)
        ax.set_title(f"E[e_{names[i]} · x̂_{names[l]}]  (element {i + 1},{l + 1})")
        ax.set_ylabel(label("E[e x̂]", unit_product(units[i], units[l])))
    for n in range(len(cells), rows * cols):
        axes[n // cols, n % cols].set_visible(False)
    for c in range(cols):
        axes[-1, c].set_xlabel(time_label())
    legend_below(figure, axes[:1, :1].ravel())
    figure.suptitle(f"{title} (N = {count:,}; zero for an optimal filter)")
    return save(figure, path)


@styled
def plot_orthogonality_diagonal(dataset: xr.Dataset, path: str | Path) -> Path:
    """Diagonal elements E[e_i xhat_i](t) of the orthogonality matrix E[e xhat^T] (report 5.11).

    Band: +- z sqrt(E[e_i^2] E[xhat_l^2] / N), z the normal quantile for K d^2 comparisons (the
    ``orthogonality`` check). 900 x (150 + 250 d) px.

    Parameters
    ----------
    dataset : xarray.Dataset
        A ``stats.nc`` Dataset (attributes ``realizations`` and ``confidence``).
    path : path of the PNG to write
    """
    d = dataset.sizes["state"]
    return _orthogonality(dataset, [(i, i) for i in range(d)], 1, path, "Orthogonality of error and estimate, E[e x̂ᵀ] diagonal")


@styled
def plot_orthogonality_offdiagonal(dataset: xr.Dataset, path: str | Path) -> Path:
    """Off-diagonal elements E[e_i xhat_l](t), i != l, of E[e xhat^T] (report 5.12); row i holds e_i.

    Band as in :func:`plot_orthogonality_diagonal`. d rows of d - 1 panels: 900 x (150 + 250 d) px.

    Parameters
    ----------
    dataset : xarray.Dataset
        A ``stats.nc`` Dataset (attributes ``realizations`` and ``confidence``).
    path : path of the PNG to write
    """
    d = dataset.sizes["state"]
    cells = [(i, l) for i in range(d) for l in range(d) if l != i]
    return _orthogonality(dataset, cells, max(1, d - 1), path, "Orthogonality of error and estimate, E[e x̂ᵀ] off-diagonal")


@styled
def plot_sigma_exact(dataset: xr.Dataset, exact_cov: np.ndarray, path: str | Path) -> Path:
    """Three 1-sigma curves per state in time: the filter's sqrt(P_ii), the exact sqrt(P_true,ii) of the
    covariance analysis and the ensemble's s_i, one panel per state.

    The band about the exact curve is the self-check's (:mod:`kalcal.stats.self_check`): the
    ensemble variance s^2 lies in P_true,ii [q_lo, q_hi], the chi-square(N - 1) / (N - 1) quantiles for
    the self-check's ``error_variance`` comparisons (K d less those of zero exact variance) at its share of
    the run's alpha, so a correct engine keeps s inside it everywhere (at the run's confidence). The filter's curve apart from the exact one is the mistuning, seen without
    sampling noise. 900 x (150 + 250 d) px.

    Parameters
    ----------
    dataset : xarray.Dataset
        A ``stats.nc`` Dataset: ``error_cov``, ``filter_cov`` (K, d, d), attributes ``realizations`` and
        ``confidence``.
    exact_cov : ndarray, shape (K, d, d)
        P_true at every update, in the states' units squared.
    path : path of the PNG to write
    """
    times, count, confidence = _run(dataset)
    names, units = _names(dataset)
    ensemble = np.sqrt(np.diagonal(dataset["error_cov"].values, axis1=1, axis2=2))
    filt = np.sqrt(np.diagonal(dataset["filter_cov"].values, axis1=1, axis2=2))
    exact = np.sqrt(np.clip(np.diagonal(np.asarray(exact_cov), axis1=1, axis2=2), 0.0, None))
    low, high = variance_ratio_band(confidence, int(compared_states(exact_cov).sum()), count)  # the self-check's count
    figure, axes = new_figure(len(names))
    for i, (name, unit) in enumerate(zip(names, units)):
        ax = axes[i, 0]
        shade_band(ax, times, exact[:, i] * np.sqrt(low), exact[:, i] * np.sqrt(high), f"self-check band ({percent(confidence)})")
        ax.plot(times, exact[:, i], color=BAND, linewidth=1.4, label="exact σ (√P_true, covariance analysis)")
        ax.plot(times, filt[:, i], color=FILTER, linestyle="--", linewidth=1.2, label="filter σ (√P)")
        ax.plot(times, ensemble[:, i], color=ENSEMBLE, linewidth=0.9, label=f"ensemble σ (N = {count:,})")
        if np.all(exact[:, i] > 0) and np.all(filt[:, i] > 0):
            ax.set_yscale("log")
        ax.set_ylabel(label(f"σ of {name}", unit))
    axes[-1, 0].set_xlabel(time_label())
    legend_below(figure, axes[0])
    axes[0, 0].set_title("Error σ: the filter's belief, the exact value and the ensemble")
    return save(figure, path)
