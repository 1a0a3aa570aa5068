"""``kalcal verify``: the Monte Carlo verification bench: its arguments checked, computed in memory, then written.

What a verification accepts (its arguments and run lengths, checked before anything runs), the run
computed in memory (:func:`compute_verification`), and its writing into its folder as one set
(:func:`save_verification`: ``stats.nc``, ``stats_long.nc``, the page, ``summary.json``).
"""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from kalcal import __version__
from kalcal.errors import ConfigError
from kalcal.core.steps import check_form
from kalcal.io.outputs import writes_outputs
from kalcal.io.results import json_document, write_json
from kalcal.io.statistics import write_statistics
from kalcal.montecarlo.progress import JobProgress, stage
from kalcal.models.config import apply_settings, section_values
from kalcal.montecarlo.accumulators import EnsembleStatistics, ensemble_statistics
from kalcal.montecarlo.engine import BLOCK_SIZE, run_monte_carlo
from kalcal.montecarlo.problem import MAX_UPDATES, capabilities_of
from kalcal.montecarlo.scenarios import build_problem
from kalcal.scenarios.protocol import require
from kalcal.stats.suite import run_checks, verdict
from kalcal.stats.whiteness import residual_pair
from kalcal.stats.dataset import statistics_dataset
from kalcal.stats.results import as_approximation, as_false_alarm
from kalcal.results.verification import VerificationResult
from kalcal.stats.self_check import exact_prediction, self_check

ENGINES = ("exact", "sampled")
#: Realizations of that study at most (the report used 5 x 10^4).
LONG_RUN_REALIZATIONS = 50_000
#: Fewest realizations a verification accepts: below it the normal approximations behind the checks'
#: bounds (mean within z se, covariance within its asymptotic spread) are too coarse to mean much.
MIN_REALIZATIONS = 100




def default_long_run(scenario) -> float:
    """The long run's horizon (s) when none is given, within the :data:`MAX_UPDATES` updates that a
    realization may hold (:meth:`~kalcal.scenarios.protocol.Scenario.default_long_run`: the source report's
    120 s for accel-gps, 100 s at a 20 Hz GPS; none for the others)."""
    return scenario.default_long_run(MAX_UPDATES)


def run_length(scenario) -> tuple[int, float]:
    """(K, t_K): the filter updates of one realization and the last update's time (s), from the settings
    alone (no arrays are built): :meth:`~kalcal.scenarios.protocol.Scenario.run_length`."""
    return scenario.run_length()


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
    long run of more than :data:`MAX_UPDATES` updates per realization (``scenario.duration`` too long),
    and the log-only GNSS faults of accel-gps (:meth:`~kalcal.scenarios.protocol.Scenario.check_settings`).
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
    # an engine the scenario lacks, or a long run where its length is no setting (a model file's updates)
    require(scenario, "verify", engine=engine, long_run=bool(long_run))
    scenario.check_settings("verify")  # accel-gps: the truth's log-only GNSS faults
    count, horizon = run_length(scenario)
    _require_fits(count, "scenario.duration" if scenario.capabilities.long_run else "model.updates")
    if long_run and long_run <= horizon:
        raise ConfigError(
            f"--long-run: {long_run:g} s is not longer than the run itself ({horizon:g} s); give more, or 0 for none"
        )
    long_seconds = default_long_run(scenario) if long_run is None else long_run
    if long_seconds and long_seconds > horizon:
        long_count, _ = run_length(apply_settings(scenario, {"scenario.duration": long_seconds}))
        _require_fits(long_count, "--long-run")


def info_name(scenario) -> str:
    """The registry name of a scenario object."""
    return type(scenario).NAME


#: A run predicted (:class:`~kalcal.montecarlo.engine.RunEstimate`) to take longer than this on the machine
#: at hand (s; 24 h) is refused unless it saves a checkpoint: a day's work lost to one crash is not a risk
#: to take unasked.
MAX_RUN_SECONDS = 24 * 3600.0
#: A run predicted to take at least this long (s) is announced with its estimate before it goes on.
ANNOUNCE_SECONDS = 60.0


def duration_text(seconds: float) -> str:
    """``seconds`` in the unit a person reads best: s, min, h, days or years (3 significant digits)."""
    for unit, size, below in (("s", 1.0, 120.0), ("min", 60.0, 7200.0), ("h", 3600.0, 172800.0), ("days", 86400.0, 3.15576e8)):
        if seconds < below:
            return f"{seconds / size:.3g} {unit}"
    return f"{seconds / 3.15576e7:.3g} years"


def available_memory() -> int | None:
    """Bytes this process may still allocate, as far as the system says: the smaller of the kernel's
    ``MemAvailable`` and what the control group's ``memory.max`` leaves (cgroup v2); None where neither is
    known (another system than Linux)."""
    found = []
    try:
        with open("/proc/meminfo", encoding="ascii") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    found.append(int(line.split()[1]) * 1024)
    except (OSError, ValueError, IndexError):
        pass
    try:
        with open("/sys/fs/cgroup/memory.max", encoding="ascii") as limit_file:
            limit = limit_file.read().strip()
        if limit != "max":
            with open("/sys/fs/cgroup/memory.current", encoding="ascii") as current_file:
                found.append(max(0, int(limit) - int(current_file.read().strip())))
    except (OSError, ValueError):
        pass
    return min(found) if found else None


def run_estimate_check(
    *,
    checkpoint,
    notes=None,
    max_run_s: float | None = MAX_RUN_SECONDS,
    memory: int | None | str = "system",
    backend: str = "threads",
):
    """The Monte Carlo's ``estimate`` callback (:func:`~kalcal.montecarlo.engine.run_monte_carlo`): refuse
    a run predicted beyond ``max_run_s`` (s; None: no limit) without a ``checkpoint``, or one whose sums
    would not fit in ``memory`` (bytes; ``"system"``: :func:`available_memory`; None: not checked), with a
    :class:`~kalcal.errors.ConfigError` naming what to change; announce through ``notes(text)`` a run
    predicted to last :data:`ANNOUNCE_SECONDS` or more."""

    def check(estimate) -> None:
        rate = (
            f"{estimate.realizations_per_s:,.0f} realizations/s measured on {estimate.workers} "
            f"{'Dask threads' if backend == 'dask' else 'threads'}"
        )
        free = available_memory() if memory == "system" else memory
        if free is not None and estimate.memory_bytes > free:
            raise ConfigError(
                f"-n {estimate.total:,}: the run's sums would hold about {estimate.memory_bytes / 2**30:.3g} GiB at "
                f"once, more than the {free / 2**30:.3g} GiB available; use fewer threads (--threads) or "
                "processes (--workers), or a shorter scenario.duration"
            )
        if max_run_s is not None and checkpoint is None and estimate.total_s > max_run_s:
            raise ConfigError(
                f"-n {estimate.total:,}: estimated {duration_text(estimate.total_s)} on this machine ({rate}), more "
                f"than the {duration_text(max_run_s)} a run without a checkpoint may take; spread it over more "
                "processes (--workers N) or a cluster (--scheduler ADDRESS), or give --checkpoint FILE to run it "
                "in parts that resume"
            )
        if notes is not None and estimate.total_s >= ANNOUNCE_SECONDS:
            notes(f"estimated wall time of the Monte Carlo: {duration_text(estimate.total_s)} ({rate})")

    return check


def report_residual_pair(statistics: EnsembleStatistics, info, scenario) -> dict[str, Any] | None:
    """E[r_k r_j^T] at the scenario's pair of times (:meth:`~kalcal.scenarios.protocol.Scenario.residual_pair_times`:
    accel-gps's is the source report's, t_k = 23.8 s, t_j = 5.8 s, for its setup alone), or None where it
    names none, the run has no update at one of those times (another GPS rate or a shorter run), or no
    pairs were kept: the nearest updates would be another pair under the report's name."""
    pair = scenario.residual_pair_times()
    if pair is None or statistics.residual_second_moment is None:
        return None
    times = np.asarray(info.update_times)
    if not all(np.any(np.abs(times - t) <= 1e-6) for t in pair):
        return None
    return residual_pair(statistics, info, *pair)


def exact_analysis(scenario, problem):
    """The exact analysis of ``problem`` (the pairs kept, no budget), which both the self-check and the
    power use, where ``scenario`` has one (:attr:`~kalcal.scenarios.protocol.Capabilities.exact_analysis`);
    None for any other (each of them then says why)."""
    from kalcal.analysis.fixed_gain import analyze_problem

    return analyze_problem(problem, budget=False) if scenario.capabilities.exact_analysis else None


def left_out(info) -> dict[str, Any]:
    """``summary.json``'s ``not_checked`` (the updates no check covers, in words: a diffuse filter's diffuse
    period), ``checks_left_out`` (check -> why) and ``notes`` (what the reader should know of the model: a
    model file's known inputs), where the problem leaves something out; nothing else, so
    that every other run's summary keeps its keys."""
    out: dict[str, Any] = {}
    if info.not_checked:
        out["not_checked"] = info.not_checked
    if info.no_orthogonality:
        out["checks_left_out"] = {"orthogonality": info.no_orthogonality}
    if info.notes:
        out["notes"] = list(info.notes)
    return out


def power_summary(problem, n: int, confidence: float, analysis=None) -> dict[str, Any]:
    """``summary.json``'s ``power`` (each check's and part's power at n, from the exact analysis of the same
    problem: :func:`kalcal.stats.suite.problem_power`) and ``power_reason`` (why it is None, where it is)."""
    from kalcal.stats.suite import problem_power

    rows, reason = problem_power(problem, n, confidence, analysis)
    return {"power": rows, "power_reason": reason}


def truth_equals(analysis) -> bool | None:
    """``summary.json``'s ``power_truth_equals_filter``: whether the truth equals the filter in everything
    the checks see (:func:`kalcal.stats.power.truth_equals_filter`); None without an exact analysis."""
    from kalcal.stats.power import truth_equals_filter

    return None if analysis is None else truth_equals_filter(analysis)


def equals_filter(scenario, analysis, problem=None) -> bool:
    """Whether the run's truth equals its filter: from the exact analysis where there is one, from the
    settings where there is none (:meth:`~kalcal.scenarios.protocol.Scenario.truth_is_filter`). Then every
    failed check is a false alarm at its stated rate. A truth whose measurement noise is not Gaussian
    (``problem.truth.measurement_dof``: Student-t fixes) never equals the filter: the analysis sees its
    second moments alone, which are the filter's, and the shape check sees its law, which is not."""
    truth = getattr(problem, "truth", None)
    if getattr(truth, "measurement_dof", 0):
        return False
    if analysis is not None:
        return bool(truth_equals(analysis))
    return scenario.truth_is_filter()


def problem_effects(problem, sums, confidence: float):
    """The run's effect sizes and Cramér–Rao bound (:class:`kalcal.stats.effects.EffectSizes`) for a
    nonlinear model's filter (its capabilities' ``nonlinear``: the exact tests fail for an approximation
    at a large N, so the tolerance outcomes stand beside them); None for any other, or a run that kept
    no effect sums."""
    if not capabilities_of(problem).nonlinear or sums.effect is None:
        return None
    return problem.effect_sizes(sums, confidence)


def with_effects(check, effects):
    """``check`` with the effect sizes that stand beside it and its tolerance verdict."""
    mine = effects.of_check(check.name)
    if not mine:
        return check
    from kalcal.stats.effects import overall_outcome

    return dataclasses.replace(
        check, effect_sizes=mine, within_tolerance=all(e.within_tolerance for e in mine), tolerance_outcome=overall_outcome(mine)
    )


def effects_summary(effects, info, confidence: float) -> dict[str, Any]:
    """``summary.json``'s ``effect_sizes`` and ``cramer_rao`` (both None where the run kept none)."""
    if effects is None:
        return {"effect_sizes": None, "cramer_rao": None}
    bound = effects.cramer_rao
    crb = None
    if bound is not None:
        crb = {
            "note": (
                "a lower bound: the posterior (Bayesian) Cramér-Rao bound, which the mean squared error of every "
                "estimator, biased or not, is at least where the joint density of states and measurements is "
                "regular; lower_bound_se is the bound's own Monte Carlo error and below_bound counts the error of "
                "MSE - bound, both by the delete-one-group jackknife over the run's independent blocks (each row's "
                "below_bound_error says where the run kept too few groups and counts the MSE's error alone)"
            ),
            "jackknife_groups": bound.groups,
            "available": bound.available,
            "method": bound.reason,
            "final": bound.per_state(info.state_names, info.state_units, confidence),
            "bound_diagonal": None if bound.bound is None else np.diagonal(bound.bound, axis1=1, axis2=2).tolist(),
            "mse": bound.mse.tolist(),
            "mse_se": bound.mse_se.tolist(),
            "bound_diagonal_se": None if bound.bound_se is None else bound.bound_se.tolist(),
        }
    return {"effect_sizes": effects.as_dict(), "cramer_rao": crb}


def batch_convergence(problem, client, notes) -> dict | None:
    """``summary.json``'s ``batch_convergence`` of an iterative batch estimator: how many realizations' fits
    did not converge within ``filter.max_iterations`` (announced through ``notes`` where any did); None for
    a filter, or on Dask, whose worker processes keep their own tally."""
    batch = getattr(getattr(problem, "hooks", None), "batch", None)
    tally = getattr(batch, "convergence", None)
    if tally is None or client is not None:
        return None
    unconverged, total = (int(sum(column)) for column in zip(*tally)) if tally else (0, 0)
    limit = getattr(getattr(problem.scenario, "filter", None), "max_iterations", None)
    if unconverged and notes is not None:
        notes(f"the batch fit did not converge within filter.max_iterations = {limit} in {unconverged} of {total} "
              "realizations: their estimates are the last iterate; raise filter.max_iterations")
    return {"unconverged": unconverged, "realizations": total, "max_iterations": limit}


def compute_verification(
    scenario,
    n: int,
    seed: int,
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
    notes=None,
    max_run_s: float | None = MAX_RUN_SECONDS,
) -> VerificationResult:
    """Run n realizations and check the filter, in memory (the options are :func:`verify`'s): the
    :class:`~kalcal.results.verification.VerificationResult` it makes, nothing written.

    ``progress`` hears of ``"monte carlo"``, ``"long run"`` and ``"statistics"``: the statistics stage
    counts the files' contents as they are built (``stats.nc``, then ``stats_long.nc``), and
    :func:`save_verification` ends it when ``summary.json``'s content is complete.
    """
    check_arguments(
        scenario, n, engine=engine, confidence=confidence, long_run=long_run, batch_size=batch_size, form=form
    )
    started = time.perf_counter()
    problem, cause = build_problem(scenario, form)
    problem = problem.plan(n)  # a path with a setup (a compile) weighs it against the run
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
        estimate=run_estimate_check(
            checkpoint=checkpoint, notes=notes, max_run_s=max_run_s, backend="threads" if client is None else "dask"
        ),
    )
    statistics = ensemble_statistics(run.sums)
    convergence = batch_convergence(problem, client, notes)
    expected = problem.expected_mean_error()
    checks = run_checks(statistics, problem.info, confidence, expected, cause)
    info = problem.info
    analysis = exact_analysis(scenario, problem)  # the same filter against the same truth, without sampling
    exact = exact_prediction(problem, analysis)
    if equals_filter(scenario, analysis, problem):  # a failure is a false alarm at its stated rate, never a cause
        checks = [as_false_alarm(check) for check in checks]
    elif approximation := scenario.approximation_cause():
        # the truth is the filter's own nonlinear model: a failure is its approximation, not a model or noise error
        checks = [as_approximation(check, approximation) for check in checks]
    effects = problem_effects(problem, run.sums, confidence)
    if effects is not None:
        checks = [with_effects(check, effects) for check in checks]
    # the power by simulation of a nonlinear model's filter, where its settings ask for it (no exact analysis gives one)
    simulated = problem.simulated_power(n, seed, confidence, workers) if capabilities_of(problem).nonlinear else None
    bench = self_check(statistics, exact, confidence, info)
    attrs = {"scenario": info.scenario, "seed": seed, "engine": engine, "confidence": confidence}
    dataset = statistics_dataset(statistics, info, expected, attrs)
    long_seconds = default_long_run(scenario) if long_run is None else long_run
    has_long = bool(long_seconds and long_seconds > info.update_times[-1])
    files = 3 if has_long else 2  # stats.nc, stats_long.nc, summary.json
    built = stage(progress, "statistics") or (lambda done, total: None)
    built(1, files)
    long_summary = long_dataset = None
    if has_long:
        long_n = min(n, LONG_RUN_REALIZATIONS)
        long_scenario = apply_settings(scenario, {"scenario.duration": long_seconds})
        long_problem, _ = build_problem(long_scenario, form, residual_pairs=False)
        long_problem = long_problem.plan(long_n)
        long = run_monte_carlo(
            long_problem, long_n, seed, engine=engine, workers=workers, client=client, progress=stage(progress, "long run")
        )
        long_dataset = statistics_dataset(
            ensemble_statistics(long.sums), long_problem.info, long_problem.expected_mean_error(), attrs
        )
        built(2, files)
        long_summary = {"duration": long_seconds, "realizations": long_n, "monte_carlo_s": long.wall_s}
    summary = {
        "scenario": info.scenario,
        "settings": settings,
        "realizations": n,
        **({"batch_convergence": convergence} if convergence is not None else {}),
        "seed": seed,
        "engine": engine,
        "form": form,
        "confidence": confidence,
        "verdict": verdict(checks),
        "tests": [c.as_dict() for c in checks],
        **left_out(info),
        "self_check": bench.as_dict(),
        **power_summary(problem, n, confidence, analysis),
        "power_truth_equals_filter": truth_equals(analysis),
        "final": {
            "time": float(info.update_times[-1]),
            "states": list(info.state_names),
            "units": list(info.state_units),
            "filter_covariance": statistics.filter_cov[-1],
            "ensemble_covariance": statistics.error_cov[-1],
            "ensemble_mean_error": statistics.mean_error[-1],
            "exact_error_covariance": exact.error_cov[-1] if exact.available else None,
            "exact_mean_error": exact.mean_error[-1] if exact.available else None,
        },
        "residual_correlation": report_residual_pair(statistics, info, scenario),
        **effects_summary(effects, info, confidence),
        # the checks' power against named alternatives, by simulation (None where not asked for)
        "power_by_simulation": None if simulated is None else simulated.as_dict(),
        "model_error": {
            "cause": cause,
            "max_expected_mean_error_sigma": float(
                np.max(np.abs(expected) / np.sqrt(np.diagonal(statistics.filter_cov, axis1=1, axis2=2)))
            ),
        },
        "timing": {
            "monte_carlo_s": run.wall_s,
            # the long-run study's own Monte Carlo (0 without one): inside total_s, apart from monte_carlo_s
            "long_run_s": long_summary["monte_carlo_s"] if long_summary is not None else 0.0,
            # up to summary.json (Monte Carlo, long run, checks, statistics files), kept for older readers;
            # wall_s is the whole job, report_s the report's part of it
            "total_s": None,  # set when computed; here for its place in summary.json
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
    compute_s = time.perf_counter() - started
    summary["timing"].update(total_s=compute_s, report_s=None, wall_s=compute_s)
    return VerificationResult(
        scenario,
        summary,
        statistics,
        checks,
        dataset,
        long_dataset,
        None if checkpoint is None else Path(checkpoint),
        compute_s,
        bench,
    )


#: the files a verification run (with its report) may write, relative to its folder
OUTPUT_NAMES = ("summary.json", "stats.nc", "stats_long.nc", "report.html", "figures/*.png")


@writes_outputs("verify", names=OUTPUT_NAMES, inputs=("checkpoint",))
def save_verification(
    run: VerificationResult,
    out: str | Path,
    *,
    report: bool = False,
    realization: int = 0,
    progress: JobProgress | None = None,
    checkpoint: str | Path | None = None,
    scenario=None,
) -> VerificationResult:
    """Write a computed verification into ``out`` as one set: ``stats.nc``, ``stats_long.nc`` (with a long
    run), ``summary.json`` and, with ``report``, ``figures/`` and ``report.html`` (realization
    ``realization``). ``checkpoint`` and the files ``scenario`` was read from are never removed.

    ``summary.json``'s ``timing``: ``total_s`` is the computation plus writing the statistics files (s),
    ``report_s`` drawing the figures and page (None without a report), ``wall_s`` both. The page is drawn
    from the summary as it will be written, and ``summary.json`` written once, last. Returns the result
    as saved: its ``raw_summary`` as written (the timing covering the writing) and ``paths`` the files by key.
    """
    del checkpoint, scenario  # protected by the decorator (and the run's own, below)
    return _save(run, Path(out), report=report, realization=realization, progress=progress)


def _save(run: VerificationResult, out: Path, *, report: bool, realization: int, progress) -> VerificationResult:
    writing = time.perf_counter()
    files = 2 if run.long_statistics is None else 3
    paths = {"stats": write_statistics(out / "stats.nc", run.statistics)}
    if run.long_statistics is not None:
        paths["stats_long"] = write_statistics(out / "stats_long.nc", run.long_statistics)
    summary = {**run.raw_summary, "timing": dict(run.raw_summary["timing"])}
    timing = summary["timing"]
    elapsed = run.compute_s + (time.perf_counter() - writing)
    timing.update(total_s=elapsed, report_s=None, wall_s=elapsed)  # no report drawn (yet)
    paths["summary"] = out / "summary.json"  # written last, below
    done = stage(progress, "statistics")
    if done is not None:  # the summary's content is complete: it is written once, after the page
        done(files, files)
    if report:
        from kalcal.reporting import render as report_job  # the page joins this run's set of outputs

        drawing = time.perf_counter()
        # the page is drawn from the summary as it will be written (and as a redraw reads it) and from the
        # statistics in memory, not read back from the files just written: the same bytes as a redraw
        paths["report"] = report_job.draw_report(
            out, json_document(summary), run.statistics, run.long_statistics, realization=realization, progress=progress
        )
        paths["figures"] = out / report_job.FIGURE_DIR
        # the whole job's time, the report included, goes into the staged summary before the set is
        # put in place
        timing["report_s"] = time.perf_counter() - drawing
        timing["wall_s"] = run.compute_s + (time.perf_counter() - writing)
    write_json(paths["summary"], summary)
    return dataclasses.replace(run, raw_summary=summary, paths=paths)


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
    notes=None,
    max_run_s: float | None = MAX_RUN_SECONDS,
) -> VerificationResult:
    """Run n realizations, check the filter, write ``out/summary.json`` and ``out/stats.nc``:
    :func:`compute_verification` then :func:`save_verification`, with the folder checked first.

    ``n`` is at least :data:`MIN_REALIZATIONS` (100). ``long_run`` (s; default per scenario, 0 for none)
    adds a study of the ensemble statistics over a longer horizon with min(n, 50 000) realizations,
    without the residual pairs, in ``out/stats_long.nc``; a negative one, or one not longer than the run,
    is refused (the scenario's default is skipped when the run is already that long).
    ``client`` runs the blocks on a Dask cluster, ``batch_size`` realizations per task (rounded up to
    whole blocks); ``checkpoint`` resumes from and saves to a file. None of them changes the numbers.
    ``form`` is the filter's update form (joseph, standard or sqrt; see :mod:`kalcal.core.steps`).
    ``progress(stage, done, total)`` hears of every stage: ``"monte carlo"`` and ``"long run"`` in
    realizations, ``"statistics"`` in files (see :mod:`kalcal.montecarlo.progress`).
    ``report`` also draws ``out/figures/`` and ``out/report.html`` (showing realization ``realization``).
    ``summary.json``'s ``timing`` holds ``total_s`` (s, up to summary.json), ``report_s`` (drawing the
    figures and page; None without a report) and ``wall_s`` (the whole job, report included).
    The files are put in ``out`` together when the run ends, replacing the previous run's set there
    (:mod:`kalcal.io.outputs`); a run that fails or is interrupted leaves ``out`` as it was.
    Half a second into the Monte Carlo its wall time is estimated from the rate measured so far
    (:func:`~kalcal.api.verification.run_estimate_check`): a run predicted beyond ``max_run_s`` (s;
    default 24 h, None for no limit) without a ``checkpoint``, or whose sums would not fit in the memory
    available, is refused with a ConfigError; ``notes(text)`` hears the estimate of a run of a minute or more.
    """
    run = compute_verification(
        scenario,
        n,
        seed,
        engine=engine,
        confidence=confidence,
        workers=workers,
        progress=progress,
        command=command,
        long_run=long_run,
        client=client,
        batch_size=batch_size,
        checkpoint=checkpoint,
        form=form,
        notes=notes,
        max_run_s=max_run_s,
    )
    return save_verification(run, out, report=report, realization=realization, progress=progress)
