"""``kalcal.verify``: the Monte Carlo verification of a filter, returned as a VerificationResult."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from kalcal.api.progress import progress_callback
from kalcal.api.verification import MAX_RUN_SECONDS
from kalcal.results.verification import VerificationResult


def verify(
    scenario: Any = "accel-gps",
    n: int = 300_000,
    seed: int = 0,
    settings: Mapping[str, Any] | None = None,
    *,
    config: str | Path | None = None,
    engine: str = "exact",
    confidence: float = 0.99,
    threads: int | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    client=None,
    batch_size: int | None = None,
    checkpoint: str | Path | None = None,
    long_run: float | None = None,
    form: str = "joseph",
    progress: bool | Callable[[str, int, int], None] = False,
    out: str | Path | None = None,
    report: bool = False,
    realization: int = 0,
    command: str = "",
    notes: Callable[[str], None] | None = None,
    max_run_s: float | None = MAX_RUN_SECONDS,
    data: str | Path | None = None,
    topic: str | None = None,
) -> VerificationResult:
    """Verify a filter with a Monte Carlo: mean error, covariance, orthogonality, whiteness, NIS.

    Parameters
    ----------
    scenario : str, path, Model or scenario
        ``"accel-gps"``, ``"scale-bias"``, a model file (``.toml``), a :class:`kalcal.Model`, or a scenario
        from :func:`kalcal.load_model`.
    n : int
        Realizations (at least 100).
    seed : int
        Root seed: the same seed gives the same numbers, whatever ``threads``, ``workers``, ``batch_size``.
    settings : dict, optional
        ``{"section.key": value}``, the keys of ``--set`` (``{"truth.bias_std": 0.2}``).
        A section's table, ``{"filter": {"key": value}}``, is its dotted keys, as in TOML: a fit's
        ``settings`` go in as they are (``settings=fit.settings``).
    config : path, optional
        A TOML file of settings (``--config``).
    engine, confidence, batch_size, checkpoint, long_run, form
        As ``kalcal verify``'s options of those names (long_run in s; None: the scenario's default).
    threads : int, optional
        Local threads (default: all cores).
    workers, scheduler, client
        A local Dask cluster of ``workers`` processes, an existing cluster's address, or a Dask client.
    progress : bool or callable
        True: a progress bar on stderr; a callable: ``progress(stage, done, total)``
        (:mod:`kalcal.montecarlo.progress`); False: silence.
    out : path, optional
        Also write the run's files there, as ``kalcal verify --out`` (the folder is checked before the
        run starts); ``report`` draws the page and figures, showing realization ``realization``.
    command : str
        What ``summary.json`` records as the command.
    notes : callable, optional
        ``notes(text)`` hears what the run's user should know while it runs: the estimated wall time of a
        Monte Carlo of a minute or more, and each event of a Dask cluster's own log (a worker restarted).
    data : path, optional
        A log for a model file with a ``[data]`` table (``--data LOG``): its rows give H_k, V_k and the
        update rows, the gains are computed once from them (the same in every realization), the truth is
        simulated over those rows (:mod:`kalcal.scenarios.model_file.logged`). With the truth's b equal
        to the filter's (and no phi or h of its own) the error does not depend on the inputs u, which
        enter the estimates alone; otherwise the log's u give the error a deterministic offset, the filter's bias.
    topic : str, optional
        ``data`` a ROS bag or ULog: the topic the file's [data] table reads (``--topic``).
    max_run_s : float, optional
        A run estimated (half a second in) to take longer than this (s; default 24 h) is refused unless it
        saves a ``checkpoint``; None: no limit.

    Returns
    -------
    VerificationResult

    Raises
    ------
    KalcalError
        Any bad input (a ValueError), with one line naming the setting and the value.
    """
    from kalcal.api._scenario import resolve, with_data
    from kalcal.errors import KalcalError
    from kalcal.api.verification import check_arguments
    from kalcal.montecarlo.distributed import dask_client

    model = with_data(resolve(scenario, settings, config, models=True), data, "verify", topic)
    if threads is not None and threads < 1:
        raise KalcalError(f"--threads: expected a positive number, got {threads}")
    check_arguments(model, n, engine=engine, confidence=confidence, long_run=long_run, batch_size=batch_size, form=form)
    from kalcal.montecarlo.engine import check_seed

    check_seed(seed)  # before a cluster starts or a kernel compiles
    options = dict(
        engine=engine, confidence=confidence, workers=threads, command=command, long_run=long_run,
        batch_size=batch_size, checkpoint=checkpoint, form=form, notes=notes, max_run_s=max_run_s,
    )
    def cluster():
        """The Dask client the run computes on: the caller's, a new one for ``workers``/``scheduler``, or none."""
        if client is None and (workers is not None or scheduler is not None):
            return dask_client(workers, scheduler, notes)
        return contextlib.nullcontext(client)

    with progress_callback(progress, f"{scenario if isinstance(scenario, str) else 'model'} x {n:,}") as update:
        return _run(model, n, seed, options, cluster, update, out, report, realization)


def _run(model, n, seed, options, cluster, update, out, report, realization) -> VerificationResult:
    import dataclasses

    from kalcal.io.outputs import inputs_of, run_outputs
    from kalcal.api.verification import compute_verification
    from kalcal.api.verification import OUTPUT_NAMES, save_verification

    if out is None:
        with cluster() as client:
            return compute_verification(model, n, seed, client=client, progress=update, **options)
    # the folder is checked and locked before a Dask cluster starts or the run begins, and the run's files
    # are put in place as one set
    protect = [options["checkpoint"], *inputs_of(model)]
    with run_outputs(out, "verify", names=OUTPUT_NAMES, protect=protect) as staging:
        with cluster() as client:
            result = compute_verification(model, n, seed, client=client, progress=update, **options)
        saved = save_verification(result, staging, report=report, realization=realization, progress=update)
    final = {key: Path(out) / Path(path).relative_to(staging) for key, path in saved.paths.items()}
    # the summary as written: its timing covers the writing too
    return dataclasses.replace(saved, paths=final)
