"""``kalcal verify``: the Monte Carlo verification bench, from settings to summary.json and stats.nc."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from kalcal import __version__
from kalcal.errors import ConfigError
from kalcal.filters.steps import check_form
from kalcal.io.outputs import writes_outputs
from kalcal.io.results import write_json
from kalcal.io.statistics import statistics_dataset, write_statistics
from kalcal.jobs.progress import JobProgress, stage
from kalcal.models.config import apply_settings, section_values
from kalcal.montecarlo.accumulators import EnsembleStatistics, ensemble_statistics
from kalcal.montecarlo.engine import BLOCK_SIZE, run_monte_carlo
from kalcal.montecarlo.scenarios import build_problem
from kalcal.verify.checks import REPORT_RESIDUAL_PAIR, CheckResult, residual_pair, run_checks, verdict

ENGINES = ("exact", "sampled")
#: Horizon (s) of the extra mean-error study per scenario: the source report's figure 5.8 used 120 s.
LONG_RUN_SECONDS = {"accel-gps": 120.0}
#: Realizations of that study at most (the report used 5 x 10^4).
LONG_RUN_REALIZATIONS = 50_000
#: Fewest realizations a verification accepts: below it the normal approximations behind the checks'
#: bounds (mean within z se, covariance within its asymptotic spread) are too coarse to mean much.
MIN_REALIZATIONS = 100


#: Most filter updates one realization may have, in the run and in its long run (2000: 400 s at the
#: accel-gps default 5 Hz GPS; the default run has 150, the 120 s long run 600). A block of 4096
#: realizations holds its draws and residuals per update (about 0.2 MB per update and thread) and the
#: run keeps E[r_k r_j^T] over every pair of updates, (K p)^2 numbers: 128 MB per copy at K = 2000, p = 2.
#: Beyond it the arrays would not fit a usual machine, so the run is refused before it starts.
MAX_UPDATES = 2000


def run_length(scenario) -> tuple[int, float]:
    """(K, t_K): the filter updates of one realization and the last update's time (s), from the settings
    alone (no arrays are built)."""
    settings = scenario.scenario if hasattr(scenario, "scenario") else None
    if hasattr(settings, "n_updates"):  # accel-gps
        return settings.n_updates, settings.n_updates * settings.steps_per_update * settings.sample_period
    if hasattr(settings, "n_samples"):  # scale-bias: one update per sample
        return settings.n_samples, settings.n_samples / settings.rate
    count = int(scenario.model.updates)  # a model file: t_k = k * update_period
    return count, count * float(scenario.filter.update_period)


def _require_fits(count: int, what: str) -> None:
    if count > MAX_UPDATES:
        raise ConfigError(
            f"{what}: {count:,} filter updates per realization, more than the {MAX_UPDATES:,} whose per-update "
            f"arrays fit in memory; shorten it"
        )


def check_arguments(
    scenario,
    n: int,
    *,
    engine: str = "exact",
    confidence: float = 0.99,
    long_run: float | None = None,
    batch_size: int | None = None,
    form: str = "joseph",
) -> None:
    """Refuse, with a :class:`~kalcal.errors.ConfigError`, a verification that cannot run, before anything
    runs (the CLI calls it before it starts a Dask cluster; :func:`verify` calls it too).

    ``n`` below :data:`MIN_REALIZATIONS`, an unknown engine or form, a confidence outside (0, 1), a
    batch size below 1, a negative or non-finite ``long_run`` or one not longer than the run, and a run or
    long run of more than :data:`MAX_UPDATES` updates per realization (``scenario.duration`` too long).
    """
    if n < MIN_REALIZATIONS:
        raise ConfigError(
            f"-n: need at least {MIN_REALIZATIONS} realizations for meaningful bounds (the checks use the "
            f"normal approximation of ensemble means and covariances), got {n}"
        )
    if long_run is not None and not (math.isfinite(long_run) and long_run >= 0):
        raise ConfigError(f"--long-run: expected 0 (no long-run study) or a positive number of seconds, got {long_run:g}")
    if engine not in ENGINES:
        raise ConfigError(f"--engine: expected one of {', '.join(ENGINES)}, got {engine!r}")
    if not 0.0 < confidence < 1.0:
        raise ConfigError(f"--confidence: expected a number in (0, 1), got {confidence!r}")
    if batch_size is not None and batch_size < 1:
        raise ConfigError(f"--batch-size: expected a positive number of realizations, got {batch_size}")
    check_form(form, "--form")
    count, horizon = run_length(scenario)
    _require_fits(count, "model.updates" if hasattr(scenario, "model") else "scenario.duration")
    if long_run and long_run <= horizon:
        raise ConfigError(
            f"--long-run: {long_run:g} s is not longer than the run itself ({horizon:g} s); give more, or 0 for none"
        )
    long_seconds = LONG_RUN_SECONDS.get(info_name(scenario), 0.0) if long_run is None else long_run
    if long_seconds and long_seconds > horizon:
        long_count, _ = run_length(apply_settings(scenario, {"scenario.duration": long_seconds}))
        _require_fits(long_count, "--long-run")


def info_name(scenario) -> str:
    """The registry name of a scenario object."""
    return type(scenario).NAME


def report_residual_pair(statistics: EnsembleStatistics, info) -> dict[str, Any] | None:
    """E[r_k r_j^T] at the source report's pair (accel-gps, t_k = 23.8 s, t_j = 5.8 s), or None where the
    run has no update at one of those times (another GPS rate or a shorter run), no pairs were kept, or
    the scenario is not the report's: the nearest updates would be another pair under the report's name."""
    if info.scenario != "accel-gps" or statistics.residual_second_moment is None:
        return None
    times = np.asarray(info.update_times)
    if not all(np.any(np.abs(times - t) <= 1e-6) for t in REPORT_RESIDUAL_PAIR):
        return None
    return residual_pair(statistics, info, *REPORT_RESIDUAL_PAIR)


@dataclass(frozen=True)
class VerifyOutcome:
    """What a verification run produced."""

    summary: dict[str, Any]
    statistics: EnsembleStatistics
    checks: list[CheckResult]
    dataset: xr.Dataset
    paths: dict[str, Path]

#: the files a verification run (with its report) may write, relative to its folder
OUTPUT_NAMES = ("summary.json", "stats.nc", "stats_long.nc", "report.html", "figures/*.png")


@writes_outputs("verify", names=OUTPUT_NAMES, inputs=("checkpoint",))
def verify(
    scenario,
    n: int,
    seed: int,
    out: str | Path,
    *,
    engine: str = "exact",
    confidence: float = 0.99,
    workers: int | None = None,
    progress: JobProgress | None = None,
    command: str = "",
    long_run: float | None = None,
    client=None,
    batch_size: int | None = None,
    checkpoint: str | Path | None = None,
    form: str = "joseph",
    report: bool = False,
    realization: int = 0,
) -> VerifyOutcome:
    """Run n realizations, check the filter, write ``out/summary.json`` and ``out/stats.nc``.

    ``n`` is at least :data:`MIN_REALIZATIONS` (100). ``long_run`` (s; default per scenario, 0 for none)
    adds a study of the ensemble statistics over a longer horizon with min(n, 50 000) realizations,
    without the residual pairs, in ``out/stats_long.nc``; a negative one, or one not longer than the run,
    is refused (the scenario's default is skipped when the run is already that long).
    ``client`` runs the blocks on a Dask cluster, ``batch_size`` realizations per task (rounded up to
    whole blocks); ``checkpoint`` resumes from and saves to a file. None of them changes the numbers.
    ``form`` is the filter's update form (joseph, standard or sqrt; see :mod:`kalcal.filters.steps`).
    ``progress(stage, done, total)`` hears of every stage: ``"monte carlo"`` and ``"long run"`` in
    realizations, ``"statistics"`` in files written (see :mod:`kalcal.jobs.progress`).
    ``report`` also draws ``out/figures/`` and ``out/report.html`` (showing realization ``realization``).
    ``summary.json``'s ``timing`` holds ``total_s`` (s, up to summary.json), ``report_s`` (drawing the
    figures and page; None without a report) and ``wall_s`` (the whole job, report included).
    The files are put in ``out`` together when the run ends, replacing the previous run's set there
    (:mod:`kalcal.io.outputs`); a run that fails or is interrupted leaves ``out`` as it was.
    """
    check_arguments(
        scenario, n, engine=engine, confidence=confidence, long_run=long_run, batch_size=batch_size, form=form
    )
    started = time.perf_counter()
    problem, cause = build_problem(scenario, form)
    if engine not in problem.engines:
        raise ConfigError(f"--engine: {engine!r} is not available for {problem.info.scenario} (have {', '.join(problem.engines)})")
    settings = section_values(scenario)
    run = run_monte_carlo(
        problem,
        n,
        seed,
        engine=engine,
        workers=workers,
        progress=stage(progress, "monte carlo"),
        client=client,
        blocks_per_task=-(-(batch_size or BLOCK_SIZE) // BLOCK_SIZE),
        checkpoint=checkpoint,
        # the form joins the key only when it is not the default, so that older checkpoints still resume
        checkpoint_key={
            "scenario": info_name(scenario),
            "settings": settings,
            **({"form": form} if form != "joseph" else {}),
        },
    )
    statistics = ensemble_statistics(run.sums)
    expected = problem.expected_mean_error()
    checks = run_checks(statistics, problem.info, confidence, expected, cause)
    info = problem.info
    dataset = statistics_dataset(
        statistics,
        info,
        expected,
        {"scenario": info.scenario, "seed": seed, "engine": engine, "confidence": confidence},
    )
    out = Path(out)
    long_seconds = LONG_RUN_SECONDS.get(info.scenario, 0.0) if long_run is None else long_run
    has_long = bool(long_seconds and long_seconds > info.update_times[-1])
    files = 3 if has_long else 2  # stats.nc, stats_long.nc, summary.json
    file_written = stage(progress, "statistics") or (lambda done, total: None)
    paths = {"stats": write_statistics(out / "stats.nc", dataset)}
    file_written(1, files)
    long_summary = None
    if has_long:
        long_n = min(n, LONG_RUN_REALIZATIONS)
        long_scenario = apply_settings(scenario, {"scenario.duration": long_seconds})
        long_problem, _ = build_problem(long_scenario, form, residual_pairs=False)
        long = run_monte_carlo(
            long_problem, long_n, seed, engine=engine, workers=workers, client=client, progress=stage(progress, "long run")
        )
        long_stats = ensemble_statistics(long.sums)
        long_dataset = statistics_dataset(
            long_stats,
            long_problem.info,
            long_problem.expected_mean_error(),
            {"scenario": info.scenario, "seed": seed, "engine": engine, "confidence": confidence},
        )
        paths["stats_long"] = write_statistics(out / "stats_long.nc", long_dataset)
        file_written(2, files)
        long_summary = {"duration": long_seconds, "realizations": long_n, "monte_carlo_s": long.wall_s}
    summary = {
        "scenario": info.scenario,
        "settings": settings,
        "realizations": n,
        "seed": seed,
        "engine": engine,
        "form": form,
        "confidence": confidence,
        "verdict": verdict(checks),
        "tests": [c.as_dict() for c in checks],
        "final": {
            "time": float(info.update_times[-1]),
            "states": list(info.state_names),
            "units": list(info.state_units),
            "filter_covariance": statistics.filter_cov[-1],
            "ensemble_covariance": statistics.error_cov[-1],
            "ensemble_mean_error": statistics.mean_error[-1],
        },
        "residual_correlation": report_residual_pair(statistics, info),
        "model_error": {
            "cause": cause,
            "max_expected_mean_error_sigma": float(
                np.max(np.abs(expected) / np.sqrt(np.diagonal(statistics.filter_cov, axis1=1, axis2=2)))
            ),
        },
        "timing": {
            "monte_carlo_s": run.wall_s,
            # up to summary.json (Monte Carlo, long run, checks, statistics files), kept for older readers;
            # wall_s is the whole job, report_s the report's part of it
            "total_s": time.perf_counter() - started,
            "realizations_per_s": n / run.wall_s if run.wall_s > 0 else None,
            "workers": run.workers,
            "backend": "dask" if client is not None else "threads",
            "resumed_blocks": run.resumed_blocks,
            "normals_per_realization": problem.normals_per_realization(engine),
        },
        "long_run": long_summary,
        "command": command,
        "kalcal_version": __version__,
    }
    summary["timing"]["report_s"] = None  # no report drawn
    summary["timing"]["wall_s"] = time.perf_counter() - started
    paths["summary"] = write_json(out / "summary.json", summary)
    file_written(files, files)
    if report:
        from kalcal.jobs.report import FIGURE_DIR, render_report  # the page joins this run's set of outputs

        drawing = time.perf_counter()
        paths["report"] = render_report(out, realization=realization, progress=progress)
        paths["figures"] = out / FIGURE_DIR
        # the whole job's time, the report included, rewritten into the staged summary before the set
        # is put in place
        summary["timing"]["report_s"] = time.perf_counter() - drawing
        summary["timing"]["wall_s"] = time.perf_counter() - started
        write_json(out / "summary.json", summary)
    return VerifyOutcome(summary, statistics, checks, dataset, paths)
