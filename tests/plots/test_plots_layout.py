"""The figures' constrained layout holds their texts: nothing is clipped at the figure's edge and no
panel's labels run into another panel; the PNGs are reproducible."""

import dataclasses
import subprocess
import sys

import numpy as np
import pytest
from matplotlib.text import Text

from kalcal.plots import _common, consistency, ensemble, steady_state
from kalcal.plots import realization as single

from test_plots_figures import FIGURES
from tests._helpers import tree


@pytest.fixture
def saved(monkeypatch):
    """The matplotlib Figure each plot function saves, in order."""
    figures = []
    for module in (single, consistency, ensemble, steady_state):
        original = module.save

        def save(figure, path, original=original):
            written = original(figure, path)
            figures.append(figure)
            return written

        monkeypatch.setattr(module, "save", save)
    return figures


def _undrawn(figure):
    """Tick labels of ticks outside their axis's view interval, which matplotlib keeps but does not draw."""
    hidden = set()
    for ax in figure.axes:
        for axis in (ax.xaxis, ax.yaxis):
            low, high = sorted(axis.get_view_interval())
            for tick in axis.get_major_ticks() + axis.get_minor_ticks():
                loc = tick.get_loc()
                if loc is None or not low - 1e-9 * abs(high - low) <= loc <= high + 1e-9 * abs(high - low):
                    hidden.update((tick.label1, tick.label2))
    return hidden


def _texts(artist):
    hidden = _undrawn(artist)
    return [t for t in artist.findobj(Text) if t.get_visible() and t.get_text().strip() and t not in hidden]


def _panel_texts(ax):
    """The texts a panel draws outside itself: tick labels, offset text, axis labels, title."""
    hidden = _undrawn(ax.figure)
    ticks = [tick.label1 for axis in (ax.xaxis, ax.yaxis) for tick in axis.get_major_ticks() if tick.label1 not in hidden]
    texts = [*ax.texts, *ticks, ax.xaxis.label, ax.yaxis.label, ax.title]
    return [t for t in texts if t.get_visible() and t.get_text().strip()]


def assert_laid_out(figure):
    renderer = figure.canvas.get_renderer()
    width, height = figure.bbox.width, figure.bbox.height
    for text in _texts(figure):
        box = text.get_window_extent(renderer)
        if not np.all(np.isfinite(box.get_points())):
            continue  # a label of a spare tick matplotlib keeps but does not draw
        assert box.x0 >= -0.5 and box.y0 >= -0.5, f"{text.get_text()!r} clipped at the left or bottom: {box}"
        assert box.x1 <= width + 0.5 and box.y1 <= height + 0.5, f"{text.get_text()!r} clipped at the right or top: {box}"
    panels = [ax for ax in figure.axes if ax.get_visible()]
    for ax in panels:
        for text in _panel_texts(ax):
            box = text.get_window_extent(renderer)
            for other in panels:
                if other is not ax:
                    assert not box.overlaps(other.bbox), f"{text.get_text()!r} runs into another panel"
    for legend in figure.legends:  # a legend of the whole figure sits below the panels and their texts
        box = legend.get_window_extent(renderer)
        assert box.x0 >= -0.5 and box.y0 >= -0.5 and box.x1 <= width + 0.5 and box.y1 <= height + 0.5, f"legend clipped: {box}"
        for ax in panels:
            assert box.y1 <= ax.bbox.y0 and not box.overlaps(ax.bbox), "the figure's legend runs into a panel"
            for text in _panel_texts(ax):
                assert not box.overlaps(text.get_window_extent(renderer)), f"the legend covers {text.get_text()!r}"
    if figure._suptitle is not None:
        box = figure._suptitle.get_window_extent(renderer)
        for ax in panels:
            assert not box.overlaps(ax.bbox), "the figure's title runs into a panel"
            for text in _panel_texts(ax):
                assert not box.overlaps(text.get_window_extent(renderer)), f"the title covers {text.get_text()!r}"


@pytest.mark.parametrize(("name", "draw", "size"), FIGURES, ids=[f[0] for f in FIGURES])
def test_no_text_is_clipped_or_runs_into_another_panel(plots_run, saved, tmp_path, name, draw, size):
    stats, long_stats, data = plots_run
    draw(stats, long_stats, data, tmp_path / f"{name}.png")
    assert_laid_out(saved[-1])


SHARED_LEGEND = {
    "variance_diagonal": ensemble.plot_variance_diagonal,
    "variance_offdiagonal": ensemble.plot_variance_offdiagonal,
    "orthogonality_diagonal": ensemble.plot_orthogonality_diagonal,
    "orthogonality_offdiagonal": ensemble.plot_orthogonality_offdiagonal,
    # the filter's P stands in for the exact covariance: the layout is what is tested
    "sigma_exact": lambda stats, path: ensemble.plot_sigma_exact(stats, stats["filter_cov"].values, path),
}


@pytest.mark.parametrize("name", SHARED_LEGEND)
def test_panels_that_share_a_legend_show_it_once_below_them(plots_run, saved, tmp_path, name):
    """One legend for the figure, each entry once, instead of the same legend in every panel."""
    stats, _, _ = plots_run
    SHARED_LEGEND[name](stats, tmp_path / "figure.png")
    figure = saved[-1]
    assert len(figure.axes) >= 3
    assert [ax for ax in figure.axes if ax.get_legend() is not None] == []
    (legend,) = figure.legends
    texts = [text.get_text() for text in legend.get_texts()]
    assert len(texts) == len(set(texts)) >= 2
    panel_labels = {text for ax in figure.axes for text in ax.get_legend_handles_labels()[1]}
    assert set(texts) == panel_labels  # every labelled curve of every panel is named
    assert_laid_out(figure)


def test_wide_tick_labels_and_long_labels_get_their_room(plots_run, saved, tmp_path):
    """Values in the thousands and long names and units: the margins grow with them."""
    _, _, data = plots_run
    scaled = dataclasses.replace(
        data,
        truth=data.truth * 12345.6,
        estimate=data.estimate * 12345.6,
        error=data.error * 12345.6,
        filter_cov=data.filter_cov * 12345.6**2,
        state_names=("along_track_position_of_the_vehicle", "along_track_velocity", "accelerometer_bias"),
        state_units=("mm", "mm/s", "(mm/s^2)/√Hz"),
    )
    single.plot_state_estimate(scaled, 0, tmp_path / "state.png")
    single.plot_estimation_error_magnified(scaled, 2, tmp_path / "error.png")
    for figure in saved:
        assert_laid_out(figure)
    narrow = single.plot_state_estimate(data, 0, tmp_path / "narrow.png")
    assert narrow.is_file()
    assert saved[0].axes[0].get_position().x0 > saved[-1].axes[0].get_position().x0


def test_the_png_is_the_figures_size_without_a_software_stamp(plots_run, tmp_path):
    from PIL import Image

    path = single.plot_estimation_error(plots_run[2], 0, tmp_path / "a.png")
    with Image.open(path) as image:
        assert image.size == (_common.WIDTH_PX, _common.height_px(1))
        assert "Software" not in image.info


def test_the_same_run_in_two_processes_writes_the_same_figures_and_statistics_bytes(tmp_path):
    """docs/outputs.md and docs/verification.md: the same run gives the same bytes. Two fresh
    interpreters (no matplotlib state, font cache in memory or figure counter shared) run the same
    small verify; every PNG and stats.nc must match byte for byte. summary.json and report.html hold
    the run's timings and its command line, so they are left out."""
    args = ["-n", "2000", "--seed", "3", "--long-run", "0", "--set", "scenario.duration=6"]
    outs = [tmp_path / "first", tmp_path / "second"]
    for out in outs:
        done = subprocess.run([sys.executable, "-m", "kalcal", "verify", *args, "--out", str(out)],
                              capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr
    first, second = (tree(out) for out in outs)
    compared = sorted(name for name in first if name.endswith(".png") or name == "stats.nc")
    assert "stats.nc" in compared and sum(name.endswith(".png") for name in compared) >= 10, sorted(first)
    assert sorted(name for name in second if name.endswith(".png") or name == "stats.nc") == compared
    differing = [name for name in compared if first[name] != second[name]]
    assert not differing, differing


def test_a_figure_is_drawn_once_and_laid_out_as_constrained_layout_would(plots_run, tmp_path, monkeypatch):
    """save() runs the constrained layout once and draws once: savefig with the engine attached draws twice
    (a draw with rendering disabled for the layout, then the real one). The bytes are those of savefig with
    the engine attached."""
    from matplotlib.figure import Figure

    def figure():
        fig, axes = _common.new_figure(2, 2)
        for ax in axes.ravel():
            ax.plot([0.0, 1.0, 2.0], [1e-3, 3e-3, 2e-3], label="curve")
            ax.set_ylabel(_common.label("velocity variance", "(m/s)^2"))
        _common.legend_below(fig, axes[0])
        fig.suptitle("a title")
        return fig

    reference = tmp_path / "reference.png"
    figure().savefig(reference, format="png", dpi=_common.DPI, metadata={"Software": None})
    draws = []
    original = Figure.draw
    monkeypatch.setattr(Figure, "draw", lambda self, renderer: (draws.append(renderer), original(self, renderer))[1])
    saved = _common.save(figure(), tmp_path / "saved.png")
    assert len(draws) == 1
    assert saved.read_bytes() == reference.read_bytes()
