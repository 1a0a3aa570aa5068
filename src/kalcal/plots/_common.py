"""What every figure shares: size, style, unit strings, the sigma band and a deterministic PNG writer.

Figures are built on :class:`matplotlib.figure.Figure` with an Agg canvas (no pyplot, no global figure
manager, no interactive backend touched), laid out by matplotlib's constrained layout and rendered at a
fixed size and dpi, without ``bbox_inches="tight"``: a figure with ``rows`` rows of panels is always
``WIDTH_PX`` x ``height_px(rows)`` pixels, and the same data give the same bytes (``savefig`` writes the
PNG without a software stamp; Agg's PNGs carry no time).
"""

from __future__ import annotations

import functools
from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

DPI = 100
#: width of every figure, px
WIDTH_PX = 900
#: height of a figure with one row of panels, px; each further row adds ROW_PX
BASE_PX = 150
ROW_PX = 250

STYLE = {
    "font.size": 10.0,
    "axes.titlesize": 10.5,
    "axes.labelsize": 10.0,
    "legend.fontsize": 8.5,
    "xtick.labelsize": 9.0,
    "ytick.labelsize": 9.0,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "axes.formatter.useoffset": False,
    "axes.formatter.limits": (-3, 4),
}

#: colours by role, the same in every figure
TRUTH = "black"
ESTIMATE = "tab:blue"
SIGMA = "tab:blue"
ENSEMBLE = "tab:red"
FILTER = "black"
BAND = "tab:green"
EXPECTED = "tab:orange"
STATE_COLORS = ("tab:blue", "tab:red", "tab:green", "tab:purple", "tab:brown", "tab:olive")


def height_px(rows: int) -> int:
    """Height in pixels of a figure with ``rows`` rows of panels."""
    return BASE_PX + ROW_PX * rows


def new_figure(rows: int = 1, cols: int = 1, *, height: int | None = None, sharex: bool = True):
    """A figure of ``WIDTH_PX`` x ``height`` (default ``height_px(rows)``) pixels, in constrained layout.

    Returns
    -------
    figure : Figure
    axes : ndarray of Axes, shape (rows, cols)
    """
    height = height_px(rows) if height is None else height
    figure = Figure(figsize=(WIDTH_PX / DPI, height / DPI), dpi=DPI, layout="constrained")
    FigureCanvasAgg(figure)
    axes = figure.subplots(rows, cols, sharex=sharex, squeeze=False)
    return figure, axes


def save(figure: Figure, path: str | Path) -> Path:
    """Write ``figure`` as a PNG of exactly its pixel size, with no software or time metadata, drawn once:
    its layout engine (constrained layout) is run first and then detached, so the figure is laid out as
    drawn and then frozen (a figure is saved once)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    engine = figure.get_layout_engine()
    if engine is not None:
        # savefig with a layout engine draws the figure twice (a draw with rendering disabled that runs the
        # layout, then the real one): the layout is run here once, through the engine's own execute, and the
        # engine then let go, so that savefig draws once. The positions are the engine's: the same bytes.
        engine.execute(figure)
        figure.set_layout_engine(None)
    figure.savefig(path, format="png", dpi=DPI, metadata={"Software": None})
    return path


def styled(function):
    """Run a figure function under the shared rc style (fonts and grid are read when artists are made,
    so the whole function, saving included, runs inside the context)."""

    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        with matplotlib.rc_context(STYLE):
            return function(*args, **kwargs)

    return wrapper


def label(quantity: str, unit: str) -> str:
    """Axis label ``quantity (unit)``; no parentheses for a dimensionless quantity."""
    return f"{quantity} ({unit})" if unit else quantity


def _grouped(unit: str) -> str:
    return f"({unit})" if any(c in unit for c in "/*· ") else unit


def unit_square(unit: str) -> str:
    """The unit of a variance: ``m`` -> ``m^2``, ``m/s`` -> ``(m/s)^2``."""
    return f"{_grouped(unit)}^2" if unit else ""


def unit_product(a: str, b: str) -> str:
    """The unit of a covariance or cross moment of quantities in units ``a`` and ``b``."""
    if a == b:
        return unit_square(a)
    return f"{_grouped(a)}·{_grouped(b)}" if a and b else a or b


def time_label() -> str:
    return label("time", "s")


def shade_band(ax: Axes, times: np.ndarray, lower: np.ndarray, upper: np.ndarray, text: str, color: str = BAND):
    """Fill between ``lower`` and ``upper`` over ``times``, with ``text`` as its legend entry."""
    return ax.fill_between(times, lower, upper, color=color, alpha=0.22, linewidth=0.0, label=text)


def legend_below(figure: Figure, axes, *, ncols: int | None = None):
    """One legend for the whole figure, centred below its panels, of the labelled artists of ``axes``.

    For figures whose panels would each repeat the same legend. Entries come in the order of ``axes``
    and their artists, each label once; ``ncols`` defaults to one row of all of them. The constrained
    layout reserves its height below the panels.
    """
    handles, labels = [], []
    for ax in axes:
        for handle, text in zip(*ax.get_legend_handles_labels()):
            if text not in labels:
                handles.append(handle)
                labels.append(text)
    return figure.legend(handles, labels, loc="outside lower center", ncols=ncols or len(labels))


def percent(confidence: float) -> str:
    """``0.99`` -> ``99%`` (as many digits as needed)."""
    return f"{100.0 * confidence:g}%"
