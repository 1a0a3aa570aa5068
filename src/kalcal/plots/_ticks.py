"""Few ticks, and each axis's ticks, grid and tick labels drawn as a handful of artists.

Matplotlib draws every tick as an object of its own, two tick lines, a grid line and two texts, made
and laid out again at each draw; on the report's figures that is most of the drawing time. Here the
ticks are chosen once, when the figure is complete (at most :data:`X_BINS` and :data:`Y_BINS`
intervals on a linear axis; on a log axis decades, or denser steps (1-2-5, then 1-2-3-4-5-6-8) where
decades alone would give fewer than three labels, with no minor ticks), from the axis's own locator and formatter, and drawn as one line of tick marks,
one grid line (segments split by NaN) and one text per tick label. Log tick labels are plain text with
Unicode superscripts (``10⁻³``, ``2×10⁻⁵``) instead of mathtext.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import matplotlib
import numpy as np
from matplotlib import markers
from matplotlib.axes import Axes
from matplotlib.lines import Line2D
from matplotlib.ticker import FixedLocator, Formatter, LogFormatter, LogLocator, MaxNLocator, NullLocator
from matplotlib.transforms import ScaledTranslation, blended_transform_factory

#: at most this many intervals between ticks on a linear x or y axis
X_BINS = 7
Y_BINS = 6
#: gap between the axis's tick labels and its offset text (``1e−3``), pt (matplotlib's)
OFFSET_PAD_PT = 3.0
_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


class PowerFormatter(Formatter):
    """Log-axis tick labels in plain text: ``10⁻³`` for a decade, ``2×10⁻⁵`` between decades, and
    plain numbers from 1 to 1000."""

    def __call__(self, x, pos=None):
        if not np.isfinite(x) or x <= 0:
            return ""
        exponent = math.floor(math.log10(x) + 1e-9)
        mantissa = round(x / 10.0**exponent, 6)
        if mantissa >= 10:
            mantissa, exponent = mantissa / 10, exponent + 1
        if 0 <= exponent <= 3:
            return f"{x:g}"
        power = f"10{str(exponent).translate(_SUPERSCRIPT)}"
        return power if mantissa == 1 else f"{mantissa:g}×{power}"


def _few(axis, bins: int) -> None:
    locator = axis.get_major_locator()
    if axis.get_scale() == "log":
        low, high = sorted(axis.get_view_interval())
        if isinstance(locator, LogLocator) and low > 0 and np.isfinite(high):
            chosen = None
            for subs in ((1.0,), (1.0, 2.0, 5.0), (1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0)):  # sparse to dense
                candidate = LogLocator(base=10.0, subs=subs, numticks=bins + 3)
                shown = [v for v in candidate.tick_values(low, high) if low <= v <= high]
                if chosen is None or (len(shown) <= bins + 1 and len(chosen[1]) < 3):
                    chosen = (candidate, shown)
            axis.set_major_locator(chosen[0])
            if isinstance(axis.get_major_formatter(), LogFormatter):
                axis.set_major_formatter(PowerFormatter())
    elif isinstance(locator, MaxNLocator) and not isinstance(locator, FixedLocator):
        axis.set_major_locator(MaxNLocator(nbins=bins, steps=[1, 2, 2.5, 5, 10]))


@dataclass(frozen=True)
class AxisTicks:
    """What one axis will draw: tick positions (data units), their labels, whether the labels show,
    the offset text, and whether grid lines are drawn."""

    locs: tuple[float, ...]
    labels: tuple[str, ...]
    shown: bool
    offset: str
    grid: bool


def axis_ticks(axis, bins: int, side: str) -> AxisTicks:
    """Choose ``axis``'s few ticks (see the module docstring) and read their labels, in its final view."""
    _few(axis, bins)
    low, high = sorted(axis.get_view_interval())
    slack = (high - low) * 1e-9
    locs = [float(loc) for loc in axis.get_major_locator()() if low - slack <= loc <= high + slack]
    formatter = axis.get_major_formatter()
    labels = formatter.format_ticks(locs) if locs else []
    offset = formatter.get_offset() if hasattr(formatter, "get_offset") else ""
    params = axis.get_tick_params(which="major")
    return AxisTicks(
        tuple(locs),
        tuple(labels),
        bool(params.get(f"label{side}", True)),
        offset,
        bool(params.get("gridOn", matplotlib.rcParams["axes.grid"])),
    )


def _points(ax: Axes, x_pt: float, y_pt: float):
    return ScaledTranslation(x_pt / 72.0, y_pt / 72.0, ax.figure.dpi_scale_trans)


def draw_ticks(ax: Axes, x: AxisTicks, y: AxisTicks) -> None:
    """Replace matplotlib's ticks of ``ax`` by tick marks, grid lines and labels at ``x`` and ``y``.

    The view is frozen first (the new artists must not move it).
    """
    rc = matplotlib.rcParams
    ax.set_xlim(ax.get_xlim())
    ax.set_ylim(ax.get_ylim())
    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_locator(NullLocator())
        axis.set_minor_locator(NullLocator())
    along_x = blended_transform_factory(ax.transData, ax.transAxes)
    along_y = blended_transform_factory(ax.transAxes, ax.transData)
    grid = {"color": rc["grid.color"], "alpha": rc["grid.alpha"], "linewidth": rc["grid.linewidth"], "zorder": 1.5}
    tick = {"color": rc["xtick.color"], "markersize": rc["xtick.major.size"], "markeredgewidth": rc["xtick.major.width"]}
    pad = rc["xtick.major.size"] + rc["xtick.major.pad"]
    for ticks, along, marker in ((x, along_x, markers.TICKDOWN), (y, along_y, markers.TICKLEFT)):
        if not ticks.locs:
            continue
        locs = np.asarray(ticks.locs)
        fixed = np.zeros_like(locs)
        points = (locs, fixed) if ticks is x else (fixed, locs)
        ax.add_artist(Line2D(*points, transform=along, linestyle="none", marker=marker, clip_on=False, zorder=2.5, **tick))
        if ticks.grid:
            nan = np.full_like(locs, np.nan)
            level = np.stack([locs, locs, nan], axis=1).ravel()
            span = np.tile([0.0, 1.0, np.nan], locs.size)
            segments = (level, span) if ticks is x else (span, level)
            ax.add_artist(Line2D(*segments, transform=along, **grid))
    size = rc["xtick.labelsize"]
    if x.shown:
        place = along_x + _points(ax, 0.0, -pad)
        for loc, text in zip(x.locs, x.labels):
            ax.text(loc, 0.0, text, transform=place, ha="center", va="top", fontsize=size, clip_on=False)
    size = rc["ytick.labelsize"]
    if y.shown:
        place = along_y + _points(ax, -pad, 0.0)
        for loc, text in zip(y.locs, y.labels):
            ax.text(0.0, loc, text, transform=place, ha="right", va="center_baseline", fontsize=size, clip_on=False)
    if y.offset:
        place = ax.transAxes + _points(ax, 0.0, OFFSET_PAD_PT)
        ax.text(0.0, 1.0, y.offset, transform=place, ha="left", va="baseline", fontsize=size, clip_on=False)
    if x.offset and x.shown:
        place = ax.transAxes + _points(ax, 0.0, -pad - 1.2 * size - OFFSET_PAD_PT)
        ax.text(1.0, 0.0, x.offset, transform=place, ha="right", va="top", fontsize=size, clip_on=False)
