"""The report's figures: which to draw from a run, their files, numbers and one-line captions.

Every figure of the source report (5.1-5.12) plus NEES, NIS, the residual-correlation map and the
model-error response. Figures are drawn by :mod:`kalcal.plots`; this module only decides what goes in,
in what order, and what a reader should look for in each.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from typing import TYPE_CHECKING

import numpy as np

from kalcal.filters.steady_state import SteadyStateView
from kalcal.plots import consistency, ensemble
from kalcal.plots import realization as single
from kalcal.plots.realization_data import RealizationData
from kalcal.plots.steady_state import plot_steady_state
from kalcal.reporting.html import GROUPS, FigureEntry, SkippedFigure  # noqa: F401
from kalcal.reporting.html import page_order, sort_key
from kalcal.reporting.theory import SIGMA_EXACT, SIGMA_EXACT_TITLE, sigma_exact_spec

if TYPE_CHECKING:
    import xarray as xr

#: figures of the source report, by file stem
REPORT_NUMBERS = {
    "state_bias": "5.1",
    "state_velocity": "5.2",
    "state_position": "5.3",
    "error_position": "5.4",
    "error_velocity": "5.5",
    "error_bias": "5.6",
    "mean_error": "5.7",
    "mean_error_long": "5.8",
    "variance_diagonal": "5.9",
    "variance_offdiagonal": "5.10",
    "orthogonality_diagonal": "5.11",
    "orthogonality_offdiagonal": "5.12",
}

@dataclass(frozen=True)
class _Spec:
    key: str
    group: str
    title: str
    caption: str
    draw: Callable[[Path], Path]


def _realization_specs(data: RealizationData) -> list[_Spec]:
    specs = []
    k, last = data.index, len(data.state_names) - 1
    for i, name in enumerate(data.state_names):
        symbol = data.state_label(i)
        extra = (
            " The bias is never measured: it is inferred from the position and velocity fixes, so it converges more slowly."
            if name == "bias"
            else ""
        )
        if symbol != name and "_c" in symbol:
            extra = (
                f" The state is the error state {symbol} of the nominal that the accelerometer integrates, "
                f"not the {name} itself." + extra
            )
        specs.append(
            _Spec(
                f"state_{name}",
                "realization",
                f"True and estimated {name} state" + ("" if symbol == name else f" {symbol}") + f", realization {k}",
                f"Look for the estimate (dashed) converging onto the truth (black), with the truth inside the "
                f"shaded ±1σ band about two times in three.{extra}",
                lambda path, i=i: single.plot_state_estimate(data, i, path),
            )
        )
    for i, name in enumerate(data.state_names):
        if i == last:
            specs.append(
                _Spec(
                    f"error_{name}",
                    "realization",
                    f"Estimation error of {name} with ±1σ, whole run (a) and magnified (b), realization {k}",
                    "The bound shrinks towards zero as the state is learned, so (b) magnifies the last two thirds "
                    "of the run: the error should stay near the band there too; a long excursion to one side is the "
                    "mean error of the model (see the model-error figure), not noise.",
                    lambda path, i=i: single.plot_estimation_error_magnified(data, i, path),
                )
            )
        else:
            specs.append(
                _Spec(
                    f"error_{name}",
                    "realization",
                    f"Estimation error of {name} with ±1σ from P, realization {k}",
                    "The error x − x̂ should stay inside the filter's ±1σ band about 68% of the time and "
                    "cross zero often; a band far wider or narrower than the scatter means P is wrong.",
                    lambda path, i=i: single.plot_estimation_error(data, i, path),
                )
            )
    return specs


#: the figures of off-diagonal elements, which a one-state filter does not have
OFFDIAGONAL = {
    "variance_offdiagonal": "Ensemble covariance against the filter's covariance (off-diagonal terms of P)",
    "orthogonality_offdiagonal": "Orthogonality of error and estimate: off-diagonal elements of E[e x̂ᵀ]",
}


def _ensemble_specs(dataset: xr.Dataset, long_dataset: xr.Dataset | None, exact_cov=None) -> list[_Spec]:
    specs = [
        _Spec(
            "mean_error",
            "ensemble",
            "Ensemble mean error with its confidence band and the expected model-error mean",
            "Inside the shaded band the mean error is zero within sampling noise; where it leaves the band it "
            "should follow the dashed curve, the mean that deterministic model error alone predicts — then "
            "the model (e.g. Euler integration), not the filter, is the cause.",
            lambda path: ensemble.plot_mean_error(dataset, path),
        ),
    ]
    if long_dataset is not None:
        horizon = float(long_dataset["time"].values[-1])
        count = int(long_dataset.attrs["realizations"])
        specs.append(
            _Spec(
                "mean_error_long",
                "ensemble",
                f"Ensemble mean error over a longer run: {horizon:g} s, N = {count:,}",
                "Over the longer horizon the mean error should keep tracking the dashed model-error curve "
                "(it follows the acceleration profile); a drift away from it would be a filter error.",
                lambda path: ensemble.plot_mean_error(
                    long_dataset, path, title=f"Ensemble mean error over [0, {horizon:g}] s, N = {count:,}"
                ),
            )
        )
    one_state = dataset.sizes["state"] == 1  # no off-diagonal elements to draw
    specs += [
        _Spec(
            "variance_diagonal",
            "ensemble",
            "Ensemble variance against the filter's variance (diagonal of P)",
            "Left, the curves should overlap; right, the ratio ensemble / filter should wander about 1 inside "
            "the band: above it the filter is overconfident, below it underconfident.",
            lambda path: ensemble.plot_variance_diagonal(dataset, path),
        ),
        *([] if exact_cov is None else [_Spec(*sigma_exact_spec(dataset, exact_cov))]),
        _Spec(
            "variance_offdiagonal",
            "ensemble",
            OFFDIAGONAL["variance_offdiagonal"],
            "Left, the ensemble and filter correlations should overlap; right, the deviation of the ensemble "
            "covariance from P, in standard deviations, should stay inside ±z.",
            lambda path: ensemble.plot_variance_offdiagonal(dataset, path),
        ),
        _Spec(
            "orthogonality_diagonal",
            "ensemble",
            "Orthogonality of error and estimate: diagonal elements of E[e x̂ᵀ]",
            "For an optimal filter the error is orthogonal to the estimate: each curve should stay inside its "
            "band; a systematic excursion comes from a mean error (see the mean-error figure) or suboptimal gains.",
            lambda path: ensemble.plot_orthogonality_diagonal(dataset, path),
        ),
        _Spec(
            "orthogonality_offdiagonal",
            "ensemble",
            OFFDIAGONAL["orthogonality_offdiagonal"],
            "As for the diagonal elements: every curve should stay inside its band (row i is the error of "
            "state i against the estimate of each other state).",
            lambda path: ensemble.plot_orthogonality_offdiagonal(dataset, path),
        ),
    ]
    if one_state:
        specs = [spec for spec in specs if spec.key not in OFFDIAGONAL]
    return specs


def _consistency_specs(dataset: xr.Dataset) -> list[_Spec]:
    specs = [
        _Spec(
            "nees",
            "consistency",
            "Centered mean NEES (the covariance check's statistic) and mean NEES against time, with chi-square bounds",
            "(a) What the covariance check tests: tr(P⁻¹ Cov e), the NEES with the ensemble mean error taken "
            "out, should stay in the band around d; above it the errors spread wider than P says "
            "(overconfident), below it P is too large. (b) The raw mean of eᵀP⁻¹e, which no check tests: a "
            "mean error lifts it above (a).",
            lambda path: consistency.plot_nees(dataset, path),
        ),
        _Spec(
            "nis",
            "consistency",
            "Mean NIS against time with chi-square bounds",
            "The mean of rᵀS⁻¹r should stay in the band around p; it needs only measurements, so it is the "
            "check that also works on real data. A rise above the band means larger innovations than S.",
            lambda path: consistency.plot_nis(dataset, path),
        ),
    ]
    if "residual_second_moment" in dataset:
        specs.append(
            _Spec(
                "residual_correlation",
                "consistency",
                "Residual correlation E[r_k r_jᵀ] over pairs of update times",
                "White innovations give pale, structureless noise within the bound marked on the colour bar; "
                "a coloured block means innovations correlated in time (here, a growing mean residual).",
                lambda path: consistency.plot_residual_correlation(dataset, path),
            )
        )
    specs.append(
        _Spec(
            "model_error",
            "consistency",
            "Deterministic model-error response in units of the filter's σ",
            "The mean error that the truth's departure from the filter's model alone produces: values near "
            "±1σ shift the filter's bounds by a whole sigma; the measured means (dots) should lie on the curves.",
            lambda path: consistency.plot_model_error(dataset, path),
        )
    )
    return specs


def _steady_state_spec(steady: SteadyStateView) -> _Spec:
    def draw(path: Path) -> Path:
        return plot_steady_state(
            steady.times,
            np.diagonal(steady.posterior_cov, axis1=1, axis2=2),
            np.diagonal(steady.result.posterior_cov),
            steady.state_names,
            steady.state_units,
            path,
            stabilizing=steady.result.stabilizing,
            converged_time=steady.converged_time(),
        )

    caption = (
        "Each variance of the time-varying filter should flatten onto the dashed steady-state value from the "
        "discrete algebraic Riccati equation; a dotted line marks where ||P_k − P∞|| / ||P∞|| stays below 1e-3 "
        "(none when that is not within the run)."
        if steady.result.stabilizing
        else "The dashed lines are the DARE's solution, which is not stabilizing (see the table): a variance "
        "without a dashed line (zero in that solution) keeps shrinking and never settles."
    )
    return _Spec("steady_state", "steady_state", "Filter variance P_k against the steady state P∞", caption, draw)


def render_figures(
    dataset: xr.Dataset,
    data: RealizationData,
    figure_dir: str | Path,
    long_dataset: xr.Dataset | None = None,
    *,
    source_report: bool = True,
    steady: SteadyStateView | None = None,
    progress: Callable[[int, int], None] | None = None,
    exact_cov: np.ndarray | None = None,
    exact_reason: str | None = None,
) -> tuple[list[FigureEntry], list[SkippedFigure]]:
    """Draw every figure of the report into ``figure_dir``, one after another, in this process.

    Parameters
    ----------
    dataset : xarray.Dataset
        The run's ``stats.nc``: read back (``kalcal report``) or the parts the verify job keeps, drawn as
        they are (the figures read only ``dataset[name].values``, ``sizes``, ``attrs`` and ``name in
        dataset``, which both give).
    data : RealizationData
        The realization shown in the single-run figures.
    figure_dir : path
        Folder for the PNGs (created). The jobs draw into a fresh staging folder (:mod:`kalcal.io.outputs`),
        so it holds only this page's figures; a PNG already in a folder given here is left as it is.
    long_dataset : xarray.Dataset, optional
        ``stats_long.nc`` of the same run, for figure 5.8.
    source_report : bool
        Whether the run's settings are the source report's setup
        (:meth:`~kalcal.scenarios.protocol.Scenario.source_report`): only then do figures carry its numbers.
    steady : SteadyStateView, optional
        The filter's steady state, drawn against P_k (or a note saying why there is none).
    progress : callable, optional
        ``progress(done, total)`` after each figure is drawn (``total`` figures in all).
    exact_cov : ndarray, shape (K, d, d), optional
        The exact P_true of the run's problem, drawn against P and the ensemble; without it the figure
        is skipped with ``exact_reason``.

    Returns
    -------
    figures : list of FigureEntry
        In page order (report figures by number, then the rest).
    skipped : list of SkippedFigure
    """
    specs = _realization_specs(data) + _statistics_specs(dataset, long_dataset, steady, exact_cov)
    return (_draw_specs(specs, figure_dir, source_report, progress),
            _skipped(dataset, long_dataset, source_report, steady, exact_cov, exact_reason))


def _statistics_specs(dataset, long_dataset, steady: SteadyStateView | None, exact_cov) -> list[_Spec]:
    specs = _ensemble_specs(dataset, long_dataset, exact_cov) + _consistency_specs(dataset)
    if steady is not None and steady.has_matrices:
        specs.append(_steady_state_spec(steady))
    return specs


def _draw_specs(specs: list[_Spec], figure_dir: str | Path, source_report: bool, progress) -> list[FigureEntry]:
    """Draw ``specs`` into ``figure_dir`` (created); their entries in page order."""
    figure_dir = Path(figure_dir)
    figure_dir.mkdir(parents=True, exist_ok=True)
    numbers = REPORT_NUMBERS if source_report else {}
    paths = []
    for done, spec in enumerate(specs, start=1):
        paths.append(spec.draw(figure_dir / f"{spec.key}.png"))
        if progress is not None:
            progress(done, len(specs))
    figures = [
        FigureEntry(spec.key, spec.group, spec.title, spec.caption, path, numbers.get(spec.key))
        for spec, path in zip(specs, paths, strict=True)
    ]
    return page_order(figures)


def _skipped(dataset, long_dataset, source_report: bool, steady: SteadyStateView | None, exact_cov, exact_reason) -> list[SkippedFigure]:
    """The figures a page leaves out, and why, in page order."""
    numbers = REPORT_NUMBERS if source_report else {}
    skipped = []
    if long_dataset is None:
        skipped.append(
            SkippedFigure(
                "mean_error_long",
                "ensemble",
                "Ensemble mean error over a longer run",
                "this run has no stats_long.nc (kalcal verify writes it for scenarios with a longer study, "
                "unless --long-run 0 is given)",
                numbers.get("mean_error_long"),
            )
        )
    if exact_cov is None:
        skipped.append(SkippedFigure(SIGMA_EXACT, "ensemble", SIGMA_EXACT_TITLE, exact_reason or "no exact analysis was given"))
    if dataset.sizes["state"] == 1:
        skipped += [
            SkippedFigure(key, "ensemble", title, "a filter of one state has no off-diagonal elements", numbers.get(key))
            for key, title in OFFDIAGONAL.items()
        ]
    if "residual_second_moment" not in dataset:
        skipped.append(
            SkippedFigure(
                "residual_correlation",
                "consistency",
                "Residual correlation over pairs of update times",
                "stats.nc holds no E[r_k r_j^T] over pairs of updates (the run did not keep them)",
            )
        )
    if steady is not None and not steady.has_matrices:
        why = f"{'steady state does not apply' if not steady.applies else 'no stabilizing solution'}: {steady.reason}"
        skipped.append(SkippedFigure("steady_state", "steady_state", "Filter variance P_k against the steady state", why))
    return sorted(skipped, key=sort_key)
