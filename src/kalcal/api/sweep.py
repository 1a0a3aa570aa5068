"""``kalcal.sweep``: a verification per value of one setting, written with the tuning curve."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from kalcal.api.sweep_result import SweepResult


def sweep(
    scenario: str = "accel-gps",
    key: str = "",
    values: Sequence[Any] = (),
    n: int = 100_000,
    seed: int = 0,
    out: str | Path | None = None,
    settings: Mapping[str, Any] | None = None,
    *,
    config: str | Path | None = None,
    engine: str = "exact",
    threads: int | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    client=None,
):
    """Verify ``scenario`` with ``key`` (``"filter.accel_noise_std"``) set to each of ``values``, all with
    the same seed; writes (``out`` is required) ``out/sweep.csv``, ``sweep.json``, ``sweep.png`` and one run folder per value
    (as ``kalcal sweep``). Returns a :class:`kalcal.SweepResult` (``key``, ``values``, ``table``: one row
    per value with every check's statistic, bounds and verdict, ``summaries`` and ``runs``: each value's
    summary.json and folder, ``paths``: the sweep's own files)."""
    from kalcal.api._scenario import resolve
    from kalcal.errors import KalcalError

    if out is None:
        raise KalcalError("out: required (the folder for sweep.csv, sweep.png and one run per value; a sweep always writes)")
    values = [str(value) for value in values]
    if not key or len(values) < 2:
        raise KalcalError(f"sweep: give a setting and at least two values (got {key!r} with {len(values)})")
    if threads is not None and threads < 1:
        raise KalcalError(f"--threads: expected a positive number, got {threads}")
    from kalcal.jobs.sweep import sweep as run_sweep
    from kalcal.jobs.sweep import sweep_cells
    from kalcal.montecarlo.distributed import dask_client

    model = resolve(scenario, settings, config)
    sweep_cells(model, key, values, n, engine=engine, long_run=0)  # every value checked before any cluster
    options = dict(engine=engine, workers=threads, long_run=0)
    if client is None and (workers is not None or scheduler is not None):
        with dask_client(workers, scheduler) as client:
            return SweepResult.from_sweep(run_sweep(model, key, values, n, seed, out, client=client, **options), values)
    return SweepResult.from_sweep(run_sweep(model, key, values, n, seed, out, client=client, **options), values)


def sweep_settings(assignments: Sequence[str]) -> tuple[str, list[str], dict[str, str]]:
    """``--set`` assignments (``key=v1,v2,...`` among them) as the swept key, its values and the fixed settings."""
    from kalcal.jobs.sweep import split_sweep
    from kalcal.models.settings import parse_assignments

    return split_sweep(parse_assignments(assignments))
