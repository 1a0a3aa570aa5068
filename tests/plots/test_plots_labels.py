"""What the figures say: the states of accel-gps are error states, and the NEES figure shows the
statistic the covariance check tests, with the check's own bounds."""

import dataclasses
import json

import numpy as np
import pytest

from kalcal.scenarios import build_scenario
from kalcal.montecarlo.accumulators import ensemble_statistics
from kalcal.montecarlo.engine import run_monte_carlo
from kalcal.montecarlo.scenarios import build_problem
from kalcal.plots import consistency, ensemble
from kalcal.plots import realization as single
from kalcal.stats.bounds import COVARIANCE_PARTS, centered_nees_bounds
from kalcal.stats.covariance import centered_nees, check_covariance


@pytest.fixture
def captured(monkeypatch):
    """The matplotlib Figure each plot function saves, in order."""
    figures = []

    def keep(module):
        original = module.save

        def save(figure, path):
            figures.append(figure)
            return original(figure, path)

        monkeypatch.setattr(module, "save", save)

    keep(single)
    keep(consistency)
    keep(ensemble)
    return figures


def test_accel_gps_states_are_labelled_as_error_states():
    assert build_scenario("accel-gps").state_labels == ("δp = p − p_c", "δv = v − v_c", "b")
    assert build_scenario("accel-gps", None, ["truth.scale_std=1e-3", "filter.scale_std=1e-3"]).state_labels[-1] == "s"


@pytest.mark.parametrize("state, symbol", [(0, "δp = p − p_c"), (1, "δv = v − v_c"), (2, "b")])
def test_state_figure_names_the_error_state_not_the_true_velocity(plots_run, captured, tmp_path, state, symbol):
    _, _, data = plots_run
    labelled = dataclasses.replace(data, state_labels=build_scenario("accel-gps").state_labels)
    single.plot_state_estimate(labelled, state, tmp_path / "state.png")
    ax = captured[-1].axes[0]
    legend = [text.get_text() for text in ax.get_legend().get_texts()]
    assert f"true {symbol}" in legend and f"estimated {symbol.partition(' = ')[0]}" in legend
    assert symbol in ax.get_ylabel() and symbol in ax.get_title()
    name = data.state_names[state]
    assert f"true {name}" not in legend


def test_state_figure_without_labels_keeps_the_names(plots_run, captured, tmp_path):
    _, _, data = plots_run
    single.plot_state_estimate(data, 1, tmp_path / "state.png")
    legend = [text.get_text() for text in captured[-1].axes[0].get_legend().get_texts()]
    assert "true velocity" in legend


def test_nees_figure_shows_the_covariance_checks_statistic_and_bounds(plots_run, captured, tmp_path):
    stats, _, _ = plots_run
    consistency.plot_nees(stats, tmp_path / "nees.png")
    tested, raw = captured[-1].axes
    count, confidence = int(stats.attrs["realizations"]), float(stats.attrs["confidence"])
    expected = centered_nees(stats["error_cov"].values, stats["filter_cov"].values)
    (line,) = [l for l in tested.get_lines() if "centered mean NEES" in l.get_label()]
    np.testing.assert_allclose(line.get_ydata(), expected)
    low, high = centered_nees_bounds(confidence, stats.sizes["time"], stats.sizes["state"], count)
    band = tested.patches[0]  # axhspan: a rectangle spanning the axes in x, in data units in y
    assert band.get_y() == pytest.approx(low) and band.get_y() + band.get_height() == pytest.approx(high)
    assert "covariance check" in tested.get_title()
    # the band is drawn at the NEES part's share of alpha, and its legend says so (not the check's own level)
    part_level = 1.0 - (1.0 - confidence) / len(COVARIANCE_PARTS)
    assert f"{100 * part_level:g}% (alpha / {len(COVARIANCE_PARTS)})" in band.get_label()
    assert f"{100 * confidence:g}% over" not in band.get_label()
    (raw_line,) = [l for l in raw.get_lines() if "mean NEES" in l.get_label()]
    np.testing.assert_allclose(raw_line.get_ydata(), stats["mean_nees"].values)
    assert "not a check" in raw.get_title()


def test_the_figures_nees_is_the_one_the_check_holds_against_its_bounds():
    scenario = build_scenario("accel-gps", None, ["scenario.duration=2", "scenario.truth=discrete"])
    problem, _ = build_problem(scenario)
    s = ensemble_statistics(run_monte_carlo(problem, 2000, seed=5).sums)
    result = check_covariance(s, problem.info, 0.99)
    values = centered_nees(s.error_cov, s.filter_cov)
    low, high = centered_nees_bounds(0.99, s.filter_cov.shape[0], s.filter_cov.shape[1], s.count)
    (part,) = [part for part in result.parts if part.name == "centered_nees"]
    assert (part.lower, part.upper) == pytest.approx((low, high))
    # tr(L^-1 C L^-T) of the check and tr(P^-1 C) of the figure: the same number to rounding
    assert np.any(np.isclose(values, part.statistic, rtol=1e-12, atol=0))


def _band(ax) -> tuple[float, float]:
    """(lowest, highest) y of the shaded band (fill_between) of an axes."""
    (collection,) = [c for c in ax.collections if c.get_label().startswith(("1 ±", "±"))]
    y = np.concatenate([path.vertices[:, 1] for path in collection.get_paths()])
    return float(y.min()), float(y.max())


def test_variance_figures_draw_the_covariance_checks_element_bound(plots_dir, plots_run, captured, tmp_path):
    """Both covariance figures band the deviation at the bound the check holds it to: the element-wise
    part's (at alpha / 2), not the full-alpha quantile."""
    stats, _, _ = plots_run
    summary = json.loads((plots_dir / "summary.json").read_text())
    (covariance,) = [test for test in summary["tests"] if test["name"] == "covariance"]
    elements = covariance["parts"][0]
    assert elements["name"] == "elements"
    z, count = elements["upper"], int(stats.attrs["realizations"])
    ensemble.plot_variance_diagonal(stats, tmp_path / "diag.png")
    ratios = captured[-1].axes[1::2]  # the right column: C_ii / P_ii with 1 +- z sqrt(2 / N)
    assert len(ratios) == stats.sizes["state"]
    for ax in ratios:
        assert _band(ax) == pytest.approx((1 - z * np.sqrt(2 / count), 1 + z * np.sqrt(2 / count)), rel=1e-9)
    ensemble.plot_variance_offdiagonal(stats, tmp_path / "off.png")
    deviations = captured[-1].axes[1::2]  # the right column: (C_il - P_il) / sd with +- z
    assert len(deviations) == 3
    for ax in deviations:
        assert _band(ax) == pytest.approx((-z, z), rel=1e-9)


def test_nees_band_label_names_the_parts_share_of_alpha():
    assert "99.5% (alpha / 2) over 150 updates" in consistency.nees_band_label(0.99, 150, 3)
    assert "97.5% (alpha / 2)" in consistency.nees_band_label(0.95, 10, 3)
