"""The figures' margins, measured without a layout pass, hold their texts: nothing is clipped at the
figure's edge and no panel's labels run into another panel; ticks stay few and log labels plain."""

import dataclasses
import io

import numpy as np
import pytest
from matplotlib.text import Text

from kalcal.plots import _common, consistency, ensemble, steady_state
from kalcal.plots import realization as single
from kalcal.plots._ticks import X_BINS, Y_BINS, PowerFormatter

from test_plots_figures import FIGURES


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


def _texts(artist):
    return [t for t in artist.findobj(Text) if t.get_visible() and t.get_text().strip()]


def _panel_texts(ax):
    """The texts a panel draws outside itself: tick labels, offset text, axis labels, title."""
    return [t for t in [*ax.texts, ax.xaxis.label, ax.yaxis.label, ax.title] if t.get_visible() and t.get_text().strip()]


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


def test_ticks_are_few_and_log_axes_have_no_minor_ticks(plots_run, saved, tmp_path):
    stats, _, _ = plots_run
    ensemble.plot_variance_diagonal(stats, tmp_path / "variance.png")
    ensemble.plot_orthogonality_offdiagonal(stats, tmp_path / "orthogonality.png")
    for figure in saved:
        for ax in figure.axes:
            # the tick labels are the panel's own texts now; matplotlib's tick machinery draws none
            assert len(ax.xaxis.get_major_locator()()) == 0 and len(ax.yaxis.get_major_locator()()) == 0
            x_labels = [t for t in ax.texts if t.get_horizontalalignment() == "center" and t.get_verticalalignment() == "top"]
            y_labels = [t for t in ax.texts if t.get_horizontalalignment() == "right"]
            assert len(x_labels) <= X_BINS + 1 and 2 <= len(y_labels) <= Y_BINS + 1
            assert not any("$" in t.get_text() for t in ax.texts), "mathtext in a tick label"
    log_panel = saved[0].axes[0]
    assert log_panel.get_yscale() == "log" and len(log_panel.yaxis.get_minor_locator()()) == 0


@pytest.mark.parametrize(
    ("value", "text"),
    [(1e-3, "10⁻³"), (2e-5, "2×10⁻⁵"), (5e-4, "5×10⁻⁴"), (1.0, "1"), (20.0, "20"), (1000.0, "1000"), (1e5, "10⁵"), (1e-12, "10⁻¹²")],
)
def test_log_tick_labels_are_plain_text_powers_of_ten(value, text):
    assert PowerFormatter()(value) == text


def test_the_png_is_rgb_at_the_figures_size(plots_run, tmp_path):
    from PIL import Image

    path = single.plot_estimation_error(plots_run[2], 0, tmp_path / "e.png")
    with Image.open(path) as image:
        assert image.mode == "RGB" and image.size == (_common.WIDTH_PX, _common.height_px(1))
    assert np.asarray(Image.open(path)).shape == (_common.height_px(1), _common.WIDTH_PX, 3)


def test_the_png_holds_the_canvas_pixels_channel_for_channel(tmp_path):
    """The PNG is the drawn canvas less its alpha, each channel in place: a red, a green and a blue band
    come back as drawn (a reader of the RGBA rows with the channels out of order would swap them), and
    its bytes are those of numpy's copy of the three channels, which it replaced."""
    from PIL import Image

    figure, axes = _common.new_figure()
    for x, color in enumerate(("#ff0000", "#00ff00", "#0000ff")):
        axes[0, 0].axvspan(x, x + 1, color=color)
    path = _common.save(figure, tmp_path / "bands.png")
    drawn = np.asarray(figure.canvas.buffer_rgba())
    with Image.open(path) as image:
        saved = np.asarray(image)
    np.testing.assert_array_equal(saved, drawn[..., :3])
    assert np.all(drawn[..., 3] == 255)  # opaque: nothing is lost with the alpha
    for color in ([255, 0, 0], [0, 255, 0], [0, 0, 255]):
        assert np.any(np.all(saved == color, axis=-1))
    before = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(drawn[..., :3])).save(
        before, format="png", compress_level=_common.COMPRESS_LEVEL, dpi=(_common.DPI, _common.DPI)
    )
    assert path.read_bytes() == before.getvalue()
