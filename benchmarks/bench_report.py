"""The report alone: its figures as drawn now against matplotlib's constrained layout, and the PNG writer.

    python benchmarks/bench_report.py [DIR] [--repeats 3]

DIR is a ``kalcal verify`` output folder (without one, a default run is made with ``--no-report`` into
a temporary folder). Prints, measured in one run on this machine:

* ``render_report(DIR)`` (figures in parallel processes forked from this one, then the page), fastest of
  the repeats: the report as drawn in the job's own process (the job's ``timing.report_s`` draws in its
  figure process, with the realization redrawn meanwhile), and reading the statistics files, which the job
  does not; against its figures drawn in this process alone;
* matplotlib imported once before the workers fork (as now) against imported by each worker;
* each figure drawn in this process (CPU time, fastest of the repeats): as drawn now, and as drawn
  before, with constrained layout, matplotlib's own ticks and mathtext log labels, and an RGBA PNG at
  PIL's default zlib level 6; and the ratio;
* the PNG writer alone on the report's images (read back as RGBA pixels): RGB at zlib level 1, converted
  by numpy's copy of three channels or read by Pillow as RGBX (now), against RGBA at level 6, time and
  bytes;
* the shown realization redrawn (``draw_realization``, the exact engine's compiled block, warm as in a
  verify job) against numpy's redraw of it (``montecarlo.engine.realization``), fastest of the repeats.
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

import matplotlib
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from PIL import Image

import kalcal.jobs.report as report
from kalcal.reporting import figures as report_figures
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

    original = report_figures.draw_all  # render_report draws in this process: no figure process here
    report_figures.draw_all = serial
    try:
        for _ in range(repeats):
            report.render_report(run)
    finally:
        report_figures.draw_all = original
    return {name: min(values) for name, values in times.items()}


def processes_against_one(run: Path, repeats: int) -> dict[str, float]:
    """Wall time of ``render_report(run)``, s, fastest of ``repeats``: its figures drawn in processes (as
    the job draws them) and in this process alone; interleaved, so that a change in the machine's load
    falls on both alike."""
    import os

    walls: dict[str, list[float]] = {"processes": [], "one process": []}
    try:
        for _ in range(repeats):
            for name in walls:
                if name == "one process":
                    os.environ[drawing.PROCESSES_ENV] = "1"
                start = time.perf_counter()
                report.render_report(run)
                walls[name].append(time.perf_counter() - start)
                os.environ.pop(drawing.PROCESSES_ENV, None)
    finally:
        os.environ.pop(drawing.PROCESSES_ENV, None)
    return {name: min(values) for name, values in walls.items()}


#: a fresh process with what the job has loaded before its report, then matplotlib and the figures'
#: modules imported here before forking two workers (``parent``), or by each worker (``workers``)
_IMPORT = """
import multiprocessing, sys, time
import numpy, kalcal.jobs.verify
def child(_):
    import kalcal.reporting.figures
with multiprocessing.get_context("fork").Pool(2) as pool:
    pool.map(child, range(2))  # the workers started
start = time.perf_counter()
if sys.argv[1] == "parent":
    import kalcal.reporting.figures
with multiprocessing.get_context("fork").Pool(2) as pool:
    pool.map(child, range(2))
print(time.perf_counter() - start)
"""


def import_where(repeats: int) -> dict[str, float]:
    """Wall time, s, fastest of ``repeats``, from importing the figures' modules (matplotlib) to two
    forked workers holding them: imported once here and inherited, or by each worker."""
    times: dict[str, list[float]] = {"parent": [], "workers": []}
    for _ in range(repeats):
        for name in times:
            done = subprocess.run([sys.executable, "-c", _IMPORT, name], check=True, capture_output=True, text=True)
            times[name].append(float(done.stdout))
    return {name: min(values) for name, values in times.items()}


def png_writer(run: Path, repeats: int) -> None:
    """CPU time and bytes of the report's images written as PNG from RGBA pixels: as before (RGBA at zlib
    6), through numpy's copy of the three channels (RGB at zlib 1, the previous conversion), and as now
    (the RGBA rows read by Pillow as RGBX, RGB at zlib 1)."""
    images = [np.asarray(Image.open(path).convert("RGBA")) for path in sorted((run / "figures").glob("*.png"))]

    def rgba(pixels):
        return Image.fromarray(pixels)

    def numpy_copy(pixels):
        return Image.fromarray(np.ascontiguousarray(pixels[..., :3]))

    def as_rgbx(pixels):  # as plots/_common.save reads the canvas's RGBA rows
        return Image.frombytes("RGB", pixels.shape[1::-1], pixels, "raw", "RGBX")

    results = {}
    for name, image_of, level in (("RGBA, zlib 6 (before)", rgba, 6), ("RGB by numpy, zlib 1", numpy_copy, 1),
                                  ("RGB as RGBX, zlib 1 (now)", as_rgbx, 1)):  # fmt: skip
        best, size = np.inf, 0
        for _ in range(repeats):
            start, size = time.process_time(), 0
            for pixels in images:
                buffer = io.BytesIO()
                image_of(pixels).save(buffer, format="png", compress_level=level)
                size += buffer.tell()
            best = min(best, time.process_time() - start)
        results[name] = (best, size)
        print(f"  {name:26s} {best:6.3f} s  {size / 1e6:6.2f} MB")
    (before_s, before_b), _, (now_s, now_b) = results.values()
    print(f"  now / before: time {now_s / before_s:.2f}x, bytes {now_b / before_b:.2f}x")


def realization_times(run: Path, repeats: int) -> tuple[str, float, float]:
    """How the report redraws the run's realization 0 (the compiled block for the exact engine of a
    fixed-gain filter, numpy otherwise) and its wall seconds, against ``montecarlo.engine.realization``'s
    (each called once first, so that the kernel is loaded, as in the verify job that drew the run)."""
    import json

    from kalcal.montecarlo.engine import realization as numpy_realization
    from kalcal.montecarlo.scenarios import build_problem

    summary = json.loads((run / "summary.json").read_text())
    problem, _ = build_problem(report.saved_scenario(summary, run / "summary.json"), summary.get("form", "joseph"))
    args = (problem, int(summary["seed"]), 0, int(summary["realizations"]), str(summary["engine"]))

    def fastest(redraw) -> float:
        redraw(*args)
        times = []
        for _ in range(repeats):
            start = time.perf_counter()
            redraw(*args)
            times.append(time.perf_counter() - start)
        return min(times)

    how = "compiled block" if report.through_kernel(problem, args[-1]) else "numpy"
    return how, fastest(report.draw_realization), fastest(numpy_realization)


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
        workers = drawing.drawing_workers(100)
        walls = processes_against_one(run, args.repeats)
        print(f"kalcal report benchmark: matplotlib {matplotlib.__version__}\n")
        print(f"render_report in this process (reading stats.nc too), fastest of {args.repeats}:")
        print(f"  figures in {workers} processes (now):              {walls['processes']:.3f} s")
        print(f"  in one process ({drawing.PROCESSES_ENV}=1): {walls['one process']:.3f} s")
        print(f"  one process / processes: {walls['one process'] / walls['processes']:.2f}x")
        where = import_where(args.repeats)
        print("\nmatplotlib for two workers: imported here, then forked (now) | by each worker")
        print(f"  {where['parent']:.3f} s | {where['workers']:.3f} s   (workers / here {where['workers'] / where['parent']:.2f}x)")
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
        how, shown, through_numpy = realization_times(run, args.repeats)
        print(f"\nshown realization redrawn: {how} {shown:.3f} s, montecarlo.engine.realization {through_numpy:.3f} s "
              f"(ratio {through_numpy / shown:.1f}x)")


if __name__ == "__main__":
    main()
