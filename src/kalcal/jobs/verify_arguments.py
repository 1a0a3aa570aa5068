"""What a verification accepts: its arguments and run lengths, checked before anything runs."""

from __future__ import annotations

import math

from kalcal.core.steps import check_form
from kalcal.errors import ConfigError
from kalcal.models.accel_gps import AccelGpsScenario
from kalcal.models.config import apply_settings
from kalcal.montecarlo.scenarios import refuse_log_faults

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


def default_long_run(scenario) -> float:
    """The long run's horizon (s) when none is given: :data:`LONG_RUN_SECONDS`, shortened for accel-gps to
    the :data:`MAX_UPDATES` GPS intervals that a realization may hold (100 s at 20 Hz), so that a faster
    GPS is not refused by a study the user did not ask for."""
    seconds = LONG_RUN_SECONDS.get(info_name(scenario), 0.0)
    if seconds and isinstance(scenario, AccelGpsScenario):
        seconds = min(seconds, MAX_UPDATES / scenario.scenario.gps_rate)
    return seconds


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
    long run of more than :data:`MAX_UPDATES` updates per realization (``scenario.duration`` too long),
    and the log-only GNSS faults of accel-gps (:func:`~kalcal.montecarlo.scenarios.refuse_log_faults`).
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
    if isinstance(scenario, AccelGpsScenario):
        refuse_log_faults(scenario)
    count, horizon = run_length(scenario)
    _require_fits(count, "model.updates" if hasattr(scenario, "model") else "scenario.duration")
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
