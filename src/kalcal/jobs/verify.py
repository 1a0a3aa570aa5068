"""``kalcal verify``: the Monte Carlo verification bench, from settings to summary.json and stats.nc."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from kalcal import __version__
from kalcal.errors import ConfigError
from kalcal.filters.kalman import check_form
from kalcal.io.outputs import writes_outputs
from kalcal.io.results import write_json
from kalcal.io.statistics import statistics_dataset, write_statistics
from kalcal.models.config import apply_settings, section_values
from kalcal.montecarlo.accumulators import EnsembleStatistics, ensemble_statistics
from kalcal.montecarlo.engine import BLOCK_SIZE, Progress, run_monte_carlo
from kalcal.montecarlo.scenarios import build_problem
from kalcal.verify.checks import REPORT_RESIDUAL_PAIR, CheckResult, residual_pair, run_checks, verdict

ENGINES = ("exact", "sampled")
#: Horizon (s) of the extra mean-error study per scenario: the source report's figure 5.8 used 120 s.
LONG_RUN_SECONDS = {"accel-gps": 120.0}
#: Realizations of that study at most (the report used 5 x 10^4).
LONG_RUN_REALIZATIONS = 50_000


def info_name(scenario) -> str:
    """The registry name of a scenario object."""
    return type(scenario).NAME


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
    progress: Progress | None = None,
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

    ``long_run`` (s; default per scenario, 0 for none) adds a study of the ensemble statistics over a
    longer horizon with min(n, 50 000) realizations, without the residual pairs, in ``out/stats_long.nc``.
    ``client`` runs the blocks on a Dask cluster, ``batch_size`` realizations per task (rounded up to
    whole blocks); ``checkpoint`` resumes from and saves to a file. None of them changes the numbers.
    ``form`` is the filter's update form (joseph, standard or sqrt; see :mod:`kalcal.filters.kalman`).
    ``report`` also draws ``out/figures/`` and ``out/report.html`` (showing realization ``realization``).
    The files are put in ``out`` together when the run ends, replacing the previous run's set there
    (:mod:`kalcal.io.outputs`); a run that fails or is interrupted leaves ``out`` as it was.
    """
    if n < 2:
        raise ConfigError(f"-n: need at least 2 realizations, got {n}")
    if engine not in ENGINES:
        raise ConfigError(f"--engine: expected one of {', '.join(ENGINES)}, got {engine!r}")
    if not 0.0 < confidence < 1.0:
        raise ConfigError(f"--confidence: expected a number in (0, 1), got {confidence!r}")
    if batch_size is not None and batch_size < 1:
        raise ConfigError(f"--batch-size: expected a positive number of realizations, got {batch_size}")
    check_form(form, "--form")
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
        progress=progress,
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
    paths = {"stats": write_statistics(out / "stats.nc", dataset)}
    long_seconds = LONG_RUN_SECONDS.get(info.scenario, 0.0) if long_run is None else long_run
    long_summary = None
    if long_seconds and long_seconds > info.update_times[-1]:
        long_n = min(n, LONG_RUN_REALIZATIONS)
        long_scenario = apply_settings(scenario, {"scenario.duration": long_seconds})
        long_problem, _ = build_problem(long_scenario, form, residual_pairs=False)
        long = run_monte_carlo(long_problem, long_n, seed, engine=engine, workers=workers, client=client)
        long_stats = ensemble_statistics(long.sums)
        long_dataset = statistics_dataset(
            long_stats,
            long_problem.info,
            long_problem.expected_mean_error(),
            {"scenario": info.scenario, "seed": seed, "engine": engine, "confidence": confidence},
        )
        paths["stats_long"] = write_statistics(out / "stats_long.nc", long_dataset)
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
        "residual_correlation": residual_pair(statistics, info, *REPORT_RESIDUAL_PAIR),
        "model_error": {
            "cause": cause,
            "max_expected_mean_error_sigma": float(
                np.max(np.abs(expected) / np.sqrt(np.diagonal(statistics.filter_cov, axis1=1, axis2=2)))
            ),
        },
        "timing": {
            "monte_carlo_s": run.wall_s,
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
    paths["summary"] = write_json(out / "summary.json", summary)
    if report:
        from kalcal.jobs.report import render_report  # the page joins this run's set of outputs

        paths["report"] = render_report(out, realization=realization)
    return VerifyOutcome(summary, statistics, checks, dataset, paths)
