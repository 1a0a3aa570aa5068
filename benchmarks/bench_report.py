"""The report alone: its figures as drawn now against matplotlib's constrained layout, and the PNG writer.

    python benchmarks/bench_report.py [DIR] [--repeats 3]

DIR is a ``kalcal verify`` output folder (without one, a default run is made with ``--no-report`` into
a temporary folder). Prints, measured in one run on this machine:

* ``render_report(DIR)`` as the job runs it (figures in parallel processes, then the page), fastest of
  the repeats: the job's ``timing.report_s``;
* each figure drawn in this process (CPU time, fastest of the repeats): as drawn now, and as drawn
  before, with constrained layout, matplotlib's own ticks and mathtext log labels, and an RGBA PNG at
  PIL's default zlib level 6; and the ratio;
* the PNG writer alone on the report's images: RGB at zlib level 1 against RGBA at level 6, time and
  bytes.
"""

from __future__ import annotations

import argparse
import io
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from PIL import Image

import kalcal.jobs.report as report
from kalcal.plots import _common, consistency, ensemble, realization, steady_state
from kalcal.reporting import drawing

MODULES = (ensemble, consistency, realization, steady_state)


def _constrained_figure(rows=1, cols=1, *, height=None, sharex=True):
    height = _common.height_px(rows) if height is None else height
    figure = Figure(figsize=(_common.WIDTH_PX / _common.DPI, height / _common.DPI), dpi=_common.DPI, layout="constrained")
    FigureCanvasAgg(figure)
    return figure, figure.subplots(rows, cols, sharex=sharex, squeeze=False)


def _savefig(figure, path):
    figure.savefig(path, format="png", dpi=_common.DPI, metadata={"Software": None})
    return Path(path)


def _constrained_colorbar(figure, image, label, *, shrink=0.9, **_):
    colorbar = figure.colorbar(image, ax=figure.axes, shrink=shrink)
    colorbar.set_label(label)
    return colorbar


@contextmanager
def drawn_before():
    """The figures as drawn before: constrained layout, matplotlib's ticks, RGBA PNG at zlib level 6."""
    saved = [(module, name, getattr(module, name)) for module in MODULES for name in ("new_figure", "save", "colorbar_beside") if hasattr(module, name)]
    style = dict(_common.STYLE)
    try:
        for module, name, _ in saved:
            setattr(module, name, {"new_figure": _constrained_figure, "save": _savefig, "colorbar_beside": _constrained_colorbar}[name])
        _common.STYLE.pop("axes.titley", None)
        yield
    finally:
        for module, name, value in saved:
            setattr(module, name, value)
        _common.STYLE.clear()
        _common.STYLE.update(style)


def figure_times(run: Path, repeats: int) -> dict[str, float]:
    """CPU time of each figure drawn in this process, fastest of ``repeats``, s."""
    times: dict[str, list[float]] = {}

    def serial(draws, paths, workers=None, progress=None):
        for draw, path in zip(draws, paths, strict=True):
            start = time.process_time()
            draw(path)
            times.setdefault(path.name, []).append(time.process_time() - start)
        return list(paths)

    original = report.render_figures.__globals__["draw_all"]
    report.render_figures.__globals__["draw_all"] = serial
    try:
        for _ in range(repeats):
            report.render_report(run)
    finally:
        report.render_figures.__globals__["draw_all"] = original
    return {name: min(values) for name, values in times.items()}


def png_writer(run: Path, repeats: int) -> None:
    images = [np.asarray(Image.open(path).convert("RGBA")) for path in sorted((run / "figures").glob("*.png"))]
    results = {}
    for name, channels, level in (("RGBA, zlib 6 (before)", 4, 6), ("RGB, zlib 1 (now)", 3, 1)):
        best, size = np.inf, 0
        for _ in range(repeats):
            start, size = time.process_time(), 0
            for pixels in images:
                buffer = io.BytesIO()
                Image.fromarray(np.ascontiguousarray(pixels[..., :channels])).save(buffer, format="png", compress_level=level)
                size += buffer.tell()
            best = min(best, time.process_time() - start)
        results[name] = (best, size)
        print(f"  {name:22s} {best:6.3f} s  {size / 1e6:6.2f} MB")
    (before_s, before_b), (now_s, now_b) = results.values()
    print(f"  now / before: time {now_s / before_s:.2f}x, bytes {now_b / before_b:.2f}x")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", nargs="?", type=Path, help="a kalcal verify output folder (default: a new default run)")
    parser.add_argument("--repeats", type=int, default=3, help="the fastest of this many is shown")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as scratch:
        run = args.run
        if run is None:
            run = Path(scratch) / "run"
            subprocess.run([sys.executable, "-m", "kalcal", "verify", "--no-report", "--out", str(run)], check=True, stdout=subprocess.DEVNULL)
        walls = []
        for _ in range(args.repeats):
            start = time.perf_counter()
            report.render_report(run)
            walls.append(time.perf_counter() - start)
        workers = drawing.drawing_workers(100)
        print(f"render_report (the job's report_s), {workers} drawing processes: {min(walls):.3f} s (fastest of {args.repeats})")
        now = figure_times(run, args.repeats)
        with drawn_before():
            before = figure_times(run, args.repeats)
        print("\nfigures drawn in one process, CPU s (fastest of the repeats)")
        print(f"  {'figure':30s} {'before':>7s} {'now':>7s} {'ratio':>6s}")
        for name in sorted(now, key=lambda name: -before[name]):
            print(f"  {name:30s} {before[name]:7.3f} {now[name]:7.3f} {now[name] / before[name]:6.2f}")
        total_before, total_now = sum(before.values()), sum(now.values())
        print(f"  {'all':30s} {total_before:7.3f} {total_now:7.3f} {total_now / total_before:6.2f}")
        report.render_report(run)  # the folder's figures as drawn now, for the writer below
        print("\nPNG writer on the report's images")
        png_writer(run, args.repeats)


if __name__ == "__main__":
    main()
