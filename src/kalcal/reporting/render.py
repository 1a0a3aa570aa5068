"""``kalcal report``: redraw the figures and ``report.html`` of a saved verification run.

Reads ``DIR/summary.json`` and ``DIR/stats.nc`` (and ``DIR/stats_long.nc`` when present), rebuilds the
scenario from the saved settings to redraw one realization with the run's seed, and writes
``DIR/figures/*.png`` and ``DIR/report.html``. The Monte Carlo is not rerun. The same directory always
gives the same page, byte for byte, and it is the page ``kalcal verify`` drew from its run in memory
(:func:`draw_report`), without reading back the files it wrote.

The page and figures replace those of the folder's run as one set (:mod:`kalcal.io.outputs`): the
previous page stays whole until the new one is complete. ``stats_long.nc`` is drawn only when the run's
``summary.json`` says it made a long study, and only when its seed is the run's; a folder whose last
kalcal run was cut short is refused.
"""

from __future__ import annotations

import json
import operator
from collections.abc import Mapping
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from kalcal.core.steps import check_form
from kalcal.errors import ConfigError, DataError
from kalcal.io.manifest import require_complete
from kalcal.io.outputs import run_outputs
from kalcal.io.results import SCHEMA_VERSION
from kalcal.io.statistics import read_statistics
from kalcal.montecarlo.progress import JobProgress, stage
from kalcal.scenarios import scenario_of_summary, settings_assignments  # noqa: F401 (settings_assignments: this module's name for it)
from kalcal.models.settings import SettingError
from kalcal.montecarlo.engine import BLOCK_SIZE, block_generator, block_sizes
from kalcal.montecarlo.scenarios import build_problem
from kalcal.plots.realization_data import RealizationData
from kalcal.reporting.html import build_page, write_page
from kalcal.reporting.steady_state import steady_state_view
from kalcal.stats.self_check import exact_prediction

FIGURE_DIR = "figures"
PAGE = "report.html"
#: what a redraw replaces in a run's folder (glob patterns relative to it)
REPORT_OUTPUTS = (PAGE, f"{FIGURE_DIR}/*")
_REQUIRED = ("scenario", "settings", "realizations", "seed", "engine", "confidence", "tests")


def read_summary(path: Path) -> dict[str, Any]:
    """``summary.json`` of a verification run, with the keys the report needs checked.

    A ``schema_version`` above :data:`~kalcal.io.results.SCHEMA_VERSION` is refused (a DataError: its keys
    may mean something this code does not know); a summary without one is read as the layout before
    versioning, whose keys are those of version 1.
    """
    if not path.is_file():
        raise DataError(f"{path}: no such file (not a kalcal verify output directory?)")
    try:
        summary = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DataError(f"{path}: not valid JSON ({exc})") from None
    return check_summary(summary, path)


def check_summary(summary: Any, path: Path) -> dict[str, Any]:
    """:func:`read_summary`'s checks of a summary's content (read from ``path``, or about to be written there)."""
    if not isinstance(summary, dict):
        raise DataError(f"{path}: expected a JSON object, got {type(summary).__name__}")
    # schema_version: a newer layout than this code knows is refused; none at all is the layout before
    # versioning (kalcal 0.x before schema_version 1), the same keys, and is read as it is
    version = summary.get("schema_version", 0)
    if not isinstance(version, int) or isinstance(version, bool) or version < 0:
        raise DataError(f"{path}: schema_version must be a whole number >= 0, got {version!r}")
    if version > SCHEMA_VERSION:
        raise DataError(
            f"{path}: schema_version {version} is newer than this kalcal reads ({SCHEMA_VERSION}); "
            f"upgrade kalcal to redraw it"
        )
    missing = [key for key in _REQUIRED if key not in summary]
    if missing:
        raise DataError(f"{path}: missing {', '.join(missing)} (not a kalcal verify summary)")
    if not isinstance(summary["settings"], dict) or not all(isinstance(v, dict) for v in summary["settings"].values()):
        raise DataError(f"{path}: 'settings' must map sections to {{key: value}} tables")
    return summary


def _realization_index(realization: Any, count: int) -> int:
    try:
        index = operator.index(realization)
    except TypeError:
        raise ConfigError(f"--realization: expected a whole number, got {realization!r}") from None
    if not 0 <= index < count:
        raise ConfigError(f"--realization: expected 0 <= K < {count:,} (the run's realizations), got {index}")
    return index


class ShownRealization(NamedTuple):
    """The one realization the single-run figures show. K updates, d states."""

    error: np.ndarray  #: e_k = x_k - xhat_k, (K, d)
    estimate: np.ndarray  #: xhat_k, (K, d)
    filter_cov: np.ndarray  #: the filter's own P_k, (K, d, d)


def saved_scenario(summary: Mapping[str, Any], summary_path: Path):
    """The scenario a run's ``summary.json`` was drawn from: a model file's from its matrices, a built-in's
    from its settings; their errors located in ``summary_path``."""
    try:
        return scenario_of_summary(str(summary["scenario"]), summary["settings"])
    except SettingError as exc:  # the settings layer's wording, located in the summary
        raise exc.located(source=str(summary_path)) from None
    except ConfigError as exc:
        raise ConfigError(f"{summary_path}: {exc}") from None


def draw_realization(problem, seed: int, index: int, n: int, engine: str) -> ShownRealization:
    """Realization ``index`` of the n-realization ensemble drawn with ``seed``: its error, estimate and P.

    Its block is drawn whole (the draws of a block are interleaved across its realizations) and the
    problem gives this realization its cheapest way (:meth:`~kalcal.montecarlo.problem.Problem.shown_realization`:
    a fixed-gain problem's exact engine through the Monte Carlo's compiled kernel, to rounding; its sampled
    engine through numpy, bit for bit; a problem with data-dependent gains filters this series alone).
    """
    if not 0 <= index < n:
        raise ValueError(f"realization index must lie in [0, {n}), got {index}")
    block, offset = divmod(index, BLOCK_SIZE)
    rng, size = block_generator(seed, block), block_sizes(n, BLOCK_SIZE)[block]
    return ShownRealization(*problem.shown_realization(rng, size, offset, engine))


def render_report(out: str | Path, *, realization: int = 0, progress: JobProgress | None = None) -> Path:
    """Draw the figures into ``out/figures/`` and write ``out/report.html`` from a saved run.

    Parameters
    ----------
    out : path
        A ``kalcal verify`` output directory (``summary.json``, ``stats.nc``, optionally ``stats_long.nc``).
    realization : int
        Which realization of the ensemble (0-based, below the run's N) the single-run figures show.
    progress : callable, optional
        ``progress(stage, done, total)``: ``"figures"`` after each figure, ``"report"`` once the page is
        written (see :mod:`kalcal.montecarlo.progress`).

    Returns
    -------
    Path
        The page, ``out/report.html``.

    Raises
    ------
    DataError
        The directory, ``summary.json`` or ``stats.nc`` is missing or unreadable, or they disagree.
    ConfigError
        ``realization`` is not in [0, N), or the saved settings no longer build a scenario.
    OutputError
        The folder's last kalcal run did not finish, or it holds a page or figure kalcal did not write.
    """
    out = Path(out)
    if not out.is_dir():
        raise DataError(f"{out}: no such run directory")
    require_complete(out)
    summary_path = out / "summary.json"
    summary = read_summary(summary_path)
    numbers = _run_numbers(summary, summary_path, realization)  # a bad --realization: refused before stats.nc is read
    dataset = read_statistics(out / "stats.nc")
    _require_same_run(dataset, summary, out / "stats.nc", summary_path)
    long_path = out / "stats_long.nc"
    long_dataset = None
    # a stats_long.nc the run did not write (a summary without a long study) is not this run's
    if long_path.is_file() and summary.get("long_run", True) is not None:
        long_dataset = read_statistics(long_path)
        _require_same_run(long_dataset, summary, long_path, summary_path)
    return _draw_page(out, summary, dataset, long_dataset, numbers, progress)


def draw_report(
    out: str | Path,
    summary: Mapping[str, Any],
    dataset,
    long_dataset=None,
    *,
    realization: int = 0,
    progress: JobProgress | None = None,
) -> Path:
    """Draw the figures and page of a run still in memory into ``out`` (the run that writes it: ``kalcal
    verify``), without reading back the statistics files it has just written there.

    ``summary`` is ``summary.json``'s content as it will be written (:func:`kalcal.io.results.json_document`),
    ``dataset`` and ``long_dataset`` the content of ``stats.nc`` and ``stats_long.nc`` (None without a long
    run). The figures and page are the same bytes as :func:`render_report` draws from ``out`` once those
    files are there (tests/reporting/test_report_in_memory.py); the other parameters and the errors are
    its own.
    """
    out = Path(out)
    if not out.is_dir():
        raise DataError(f"{out}: no such run directory")
    require_complete(out)
    summary_path = out / "summary.json"
    summary = check_summary(dict(summary), summary_path)
    numbers = _run_numbers(summary, summary_path, realization)
    if summary.get("long_run", True) is None:
        long_dataset = None  # as a redraw ignores a stats_long.nc the summary does not own
    return _draw_page(out, summary, dataset, long_dataset, numbers, progress)


def _run_numbers(summary: dict[str, Any], summary_path: Path, realization: Any) -> tuple[int, int, int]:
    """The run's N and seed, and the index of the realization shown (checked against N)."""
    try:
        count = int(summary["realizations"])
        seed = int(summary["seed"])
    except (TypeError, ValueError):
        raise DataError(f"{summary_path}: realizations and seed must be whole numbers") from None
    return count, seed, _realization_index(realization, count)


def _draw_page(
    out: Path, summary: dict[str, Any], dataset, long_dataset, numbers: tuple[int, int, int], progress
) -> Path:
    """The figures and page of a run from its summary and statistics (read from ``out`` or in memory);
    ``numbers`` is the run's (N, seed, shown realization) as :func:`_run_numbers` checked them: the
    realization shown is redrawn first, then every figure is drawn, in this process."""
    summary_path = out / "summary.json"
    count, seed, index = numbers
    scenario = saved_scenario(summary, summary_path)
    form = str(summary.get("form", "joseph"))  # runs before --form existed used the Joseph form
    check_form(form, f"{summary_path}: form")
    problem, _ = build_problem(scenario, form)
    times = problem.info.update_times
    if dataset.sizes.get("time") != times.size or not np.allclose(dataset["time"].values, times):
        raise DataError(
            f"{out / 'stats.nc'}: its {dataset.sizes.get('time')} update times do not match the {times.size} "
            f"of the settings in {summary_path}"
        )
    if str(summary["engine"]) not in problem.engines:
        raise DataError(f"{summary_path}: engine {summary['engine']!r} is not one of {', '.join(problem.engines)}")

    steady = steady_state_view(problem)
    exact = exact_prediction(problem)  # the exact P_true, rebuilt from the settings as the problem is
    with run_outputs(
        out,
        "report",
        names=(PAGE, f"{FIGURE_DIR}/*.png"),
        replaces=REPORT_OUTPUTS,
        option=None,  # the folder is the DIR argument: there is no --out to choose
        remedy=f"to draw a page here (a folder from a kalcal version without manifests), move {PAGE} and "
        f"{FIGURE_DIR}/ out of it first",
    ) as staging:
        shown = _realization_data(problem, scenario, seed, index, count, str(summary["engine"]))
        options = dict(source_report=scenario.source_report(), steady=steady, exact_cov=exact.error_cov, exact_reason=exact.reason)
        from kalcal.reporting.figures import render_figures

        figures, skipped = render_figures(dataset, shown, staging / FIGURE_DIR, long_dataset,
                                          progress=stage(progress, "figures"), **options)  # fmt: skip
        page = build_page(summary, figures, skipped, realization=index, figure_dir_name=FIGURE_DIR, steady_state=steady)
        write_page(staging / PAGE, page)
    if progress is not None:
        progress("report", 1, 1)
    return out / PAGE


def _realization_data(problem, scenario, seed: int, index: int, count: int, engine: str) -> RealizationData:
    """What the realization figures show: realization ``index`` of the run (:func:`draw_realization`)."""
    one = draw_realization(problem, seed, index, count, engine)
    return RealizationData(
        index=index,
        times=problem.info.update_times,
        truth=one.error + one.estimate,
        estimate=one.estimate,
        error=one.error,
        filter_cov=one.filter_cov,
        state_names=tuple(problem.info.state_names),
        state_units=tuple(problem.info.state_units),
        state_labels=scenario.state_labels,
    )


def _require_same_run(dataset, summary: dict[str, Any], path: Path, summary_path: Path) -> None:
    """A statistics file whose seed or scenario is not the summary's belongs to another run."""
    for key in ("seed", "scenario"):
        saved = dataset.attrs.get(key)
        if saved is not None and str(saved) != str(summary[key]):
            raise DataError(f"{path}: from another run ({key} {saved}, {summary_path} says {summary[key]})")
