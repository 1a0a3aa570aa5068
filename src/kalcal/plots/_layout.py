"""Margins of a figure computed once from the sizes of its texts, with no layout pass.

Constrained layout draws a figure twice (once to measure every artist, once to render), and most of
that first pass is spent laying out tick labels. Here the margins come from what sits outside the
panels, measured with the renderer's font metrics and no draw: the tick labels the axes will show
(:mod:`kalcal.plots._ticks`), the axis labels, titles, offset texts, the figure's title and legends. The
panels then sit on a plain GridSpec (``subplots_adjust``), the axis labels at their measured places,
and the figure is drawn once.
"""

from __future__ import annotations

import matplotlib
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.font_manager import FontProperties

from kalcal.plots._ticks import X_BINS, Y_BINS, AxisTicks, axis_ticks, draw_ticks

#: gap between a text and the next thing, px
PAD = 5.0


def _px(value_pt: float, figure: Figure) -> float:
    return value_pt * figure.dpi / 72.0


class _Measure:
    """Width and height in px of texts, from the Agg renderer's font metrics (no draw)."""

    def __init__(self, figure: Figure):
        self.renderer = figure.canvas.get_renderer()
        self.cache: dict = {}

    def size(self, text: str, prop: FontProperties) -> tuple[float, float]:
        if not text:
            return 0.0, 0.0
        key = (text, hash(prop))
        if key not in self.cache:
            lines = text.split("\n")
            widths = [self.renderer.get_text_width_height_descent(line or " ", prop, ismath=False)[0] for line in lines]
            line_height = self.renderer.get_text_width_height_descent("lp", prop, ismath=False)[1] * 1.2
            self.cache[key] = (max(widths), line_height * len(lines))
        return self.cache[key]

    def text(self, artist) -> tuple[float, float]:
        """Size of a Text artist (rotation 0 or 90) as it stands, zero when it is empty or hidden."""
        if artist is None or not artist.get_visible() or not artist.get_text():
            return 0.0, 0.0
        width, height = self.size(artist.get_text(), artist.get_fontproperties())
        return (height, width) if artist.get_rotation() % 180 == 90 else (width, height)


def _panel_margins(ax: Axes, x: AxisTicks, y: AxisTicks, measure: _Measure) -> dict[str, float]:
    """Space one panel needs outside itself, px (left, bottom, top, right), and its tick labels' reach."""
    figure = ax.figure
    rc = matplotlib.rcParams
    x_prop, y_prop = FontProperties(size=rc["xtick.labelsize"]), FontProperties(size=rc["ytick.labelsize"])
    tick_out = _px(rc["xtick.major.size"] + rc["xtick.major.pad"], figure)
    tick_length = _px(rc["xtick.major.size"], figure)
    margins = {
        "left": tick_length if y.locs else 0.0,
        "bottom": tick_length if x.locs else 0.0,
        "top": 0.0,
        "right": 0.0,
    }
    margins["yticks"], margins["xticks"] = margins["left"], margins["bottom"]
    if y.shown and y.labels:
        margins["left"] = margins["yticks"] = tick_out + max(measure.size(text, y_prop)[0] for text in y.labels)
    ylabel_width = measure.text(ax.yaxis.label)[0]
    if ylabel_width:
        margins["left"] += _px(ax.yaxis.labelpad, figure) + ylabel_width
    if x.shown and x.labels:
        margins["bottom"] = margins["xticks"] = tick_out + measure.size(x.labels[0], x_prop)[1]
        margins["right"] = measure.size(x.labels[-1], x_prop)[0] / 2.0
        margins["left"] = max(margins["left"], measure.size(x.labels[0], x_prop)[0] / 2.0)
        if x.offset:
            margins["bottom"] += _px(3.0, figure) + measure.size(x.offset, x_prop)[1]
    xlabel_height = measure.text(ax.xaxis.label)[1]
    if xlabel_height:
        margins["bottom"] += _px(ax.xaxis.labelpad, figure) + xlabel_height
    title = max(measure.text(text)[1] for text in (ax.title, ax._left_title, ax._right_title))
    offset = measure.size(y.offset, y_prop)[1] + _px(3.0, figure) if y.offset else 0.0
    margins["top"] = max(title + _px(rc["axes.titlepad"], figure) if title else 0.0, offset)
    return margins


def fit_margins(figure: Figure, *, right_px: float = 0.0) -> None:
    """Draw the panels' few ticks and set the figure's GridSpec margins and gaps from its texts' sizes.

    Called once, when the figure is complete (by :func:`kalcal.plots._common.save`, or before a colour
    bar is added beside the panels). ``right_px`` reserves that many pixels at the right edge.
    """
    panels = [ax for ax in figure.axes if ax.get_visible() and ax.get_subplotspec() is not None]
    figure._kalcal_fitted = True
    if not panels:
        return
    ticks = [(axis_ticks(ax.xaxis, X_BINS, "bottom"), axis_ticks(ax.yaxis, Y_BINS, "left")) for ax in panels]
    measure = _Measure(figure)
    measured = [_panel_margins(ax, x, y, measure) for ax, (x, y) in zip(panels, ticks)]
    rows, cols = panels[0].get_subplotspec().get_gridspec().get_geometry()
    left, right, top, bottom = [0.0] * cols, [0.0] * cols, [0.0] * rows, [0.0] * rows
    for ax, margins in zip(panels, measured):
        spec = ax.get_subplotspec()
        first_col, last_col = spec.colspan.start, spec.colspan.stop - 1
        first_row, last_row = spec.rowspan.start, spec.rowspan.stop - 1
        left[first_col] = max(left[first_col], margins["left"])
        right[last_col] = max(right[last_col], margins["right"])
        top[first_row] = max(top[first_row], margins["top"])
        bottom[last_row] = max(bottom[last_row], margins["bottom"])
    width, height = figure.bbox.width, figure.bbox.height
    head = measure.text(figure._suptitle)[1]
    if head:
        figure._suptitle.set_y(1.0 - PAD / height)
        figure._suptitle.set_verticalalignment("top")
        head += PAD
    foot = max((legend.get_window_extent(measure.renderer).height + PAD for legend in figure.legends), default=0.0)
    left_px, right_px = left[0] + PAD, right[-1] + PAD + right_px
    top_px, bottom_px = head + top[0] + PAD, bottom[-1] + PAD + foot
    wgap = max((right[c] + left[c + 1] + 2 * PAD for c in range(cols - 1)), default=0.0)
    hgap = max((bottom[r] + top[r + 1] + 2 * PAD for r in range(rows - 1)), default=0.0)
    panel_w = (width - left_px - right_px - wgap * (cols - 1)) / cols
    panel_h = (height - top_px - bottom_px - hgap * (rows - 1)) / rows
    figure.subplots_adjust(
        left=left_px / width,
        right=1.0 - right_px / width,
        bottom=bottom_px / height,
        top=1.0 - top_px / height,
        wspace=wgap / panel_w if cols > 1 else 0.0,
        hspace=hgap / panel_h if rows > 1 else 0.0,
    )
    for ax, margins, (x, y) in zip(panels, measured, ticks):
        box = ax.get_position()
        ax.yaxis.set_label_coords(-(margins["yticks"] + _px(ax.yaxis.labelpad, figure)) / (box.width * width), 0.5)
        ax.xaxis.set_label_coords(0.5, -(margins["xticks"] + _px(ax.xaxis.labelpad, figure)) / (box.height * height))
        draw_ticks(ax, x, y)


def colorbar_beside(figure: Figure, image, label: str, *, width_px: float = 28.0, shrink: float = 0.9):
    """A colour bar of ``image`` right of the panels, at ``shrink`` of their height, labelled ``label``.

    Lays out the figure (:func:`fit_margins`) with room at the right for the bar, its tick labels and
    its label, measured like the panels' texts. Returns the Colorbar.
    """
    bar_axes = figure.add_axes((0.0, 0.0, 0.01, 0.01))
    colorbar = figure.colorbar(image, cax=bar_axes)
    colorbar.set_label(label)
    measure = _Measure(figure)
    rc = matplotlib.rcParams
    ticks = axis_ticks(bar_axes.yaxis, Y_BINS, "right")
    prop = FontProperties(size=rc["ytick.labelsize"])
    labels = max((measure.size(text, prop)[0] for text in ticks.labels), default=0.0)
    reach = _px(rc["ytick.major.size"] + rc["ytick.major.pad"], figure) + labels
    reach += _px(bar_axes.yaxis.labelpad, figure) + measure.text(bar_axes.yaxis.label)[0]
    gap = 5 * PAD  # clear of the panels' last tick label, which reaches past their right edge
    fit_margins(figure, right_px=gap + width_px + reach)
    panels = [ax.get_position() for ax in figure.axes if ax is not bar_axes and ax.get_subplotspec() is not None]
    x0 = max(box.x1 for box in panels) + gap / figure.bbox.width
    y0, y1 = min(box.y0 for box in panels), max(box.y1 for box in panels)
    height = (y1 - y0) * shrink
    bar_axes.set_position((x0, y0 + (y1 - y0 - height) / 2, width_px / figure.bbox.width, height))
    return colorbar
