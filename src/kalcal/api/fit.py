"""``kalcal.fit``: a filter's noise settings fitted to one log by maximum likelihood, returned as a FitResult."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from kalcal.fitting.result import FitResult


def _free(free: str | Sequence[str] | None) -> list[str] | None:
    """``--free``'s ``KEY,KEY`` or a list of keys; refuses an empty key (``--free ,`` is no set, not the
    default one) and a key given twice."""
    from kalcal.errors import KalcalError

    if free is None:
        return None
    items = [item.strip() for item in (free.split(",") if isinstance(free, str) else list(free))]
    given = free if isinstance(free, str) else ",".join(items)
    if not items or not all(items):
        raise KalcalError(f"--free: expected KEY,KEY... with no empty key, got {given!r}")
    twice = sorted({item for item in items if items.count(item) > 1})
    if twice:
        raise KalcalError(f"--free: {', '.join(twice)} given more than once in {given!r}")
    return items


def fit(
    scenario: str = "accel-gps",
    imu=None,
    gps=None,
    settings: Mapping[str, Any] | None = None,
    *,
    data=None,
    config: str | Path | None = None,
    free: str | Sequence[str] | None = None,
    profile: bool = False,
    gate: float | None = None,
    confidence: float = 0.95,
    init: str = "first-fix",
    imu_columns: str | None = None,
    gps_columns: str | None = None,
    reference: str = "reference",
    sensor: str = "sensor",
    out: str | Path | None = None,
    topic: str | None = None,
    bootstrap: int = 0,
    seed: int | None = None,
    threads: int | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    client=None,
) -> FitResult:
    """Fit the noise settings of a filter to one log: accel-gps (``imu``, ``gps``), scale-bias (``data``) or a
    model file (``data``, laid out as its ``[data]`` table says).

    Parameters
    ----------
    scenario : {"accel-gps", "scale-bias"}, a model file's path (``.toml``) or a :class:`kalcal.Model`
    imu, gps, data, settings, config, init, imu_columns, gps_columns, reference, sensor
        As :func:`kalcal.calibrate`.
    free : str or list of str, optional
        The settings to fit (``"filter.accel_noise_density,filter.bias_walk_density"``; a per-sample key is fitted as its density); default: accel-gps the
        accelerometer noise, bias walk and GPS noise (a multiplier on each per-fix std column the GPS log
        has), scale-bias the combined measurement noise and the drift, a model file every positive diagonal
        entry of w and v (its keys: ``filter.w``, ``filter.v.2``, ``filter.phi.1.1``, docs/custom-models.md).
    profile : bool
        Intervals from the profile likelihood instead of the observed information.
    gate : float, optional
        accel-gps: the chi-square innovation gate's confidence, as ``calibrate``'s (off by default).
    confidence : float
        Of the intervals (0.95).
    bootstrap : int or False
        B >= 2/(1 - confidence) - 1 (39 at 95%), at most 100000 (``MAX_REPLICATES``): a parametric bootstrap (:mod:`kalcal.fitting.bootstrap`): B logs simulated from the fitted
        model with the log's length, sampling, missing measurements and inputs, each refitted (a point
        estimate from the fitted point); per setting the percentile interval, the bootstrap standard error
        and the estimator's bias, in the result's ``bootstrap``, fit.json and fit-bootstrap.png. 0 or False:
        none (True is refused: it names no B).
    seed : int, optional
        The bootstrap's root seed (default 0): the same seed gives the same intervals, whatever ``threads``,
        ``workers`` or ``client``. Like ``threads``, ``workers`` and ``scheduler``, only with ``bootstrap``.
    threads : int, optional
        The bootstrap's local threads (default: all cores).
    workers, scheduler, client
        Run the bootstrap's replicates on a local Dask cluster of ``workers`` processes, an existing
        cluster's address, or a Dask client.
    out : path, optional
        Also write fit.json, filter.toml (a model file's: model.toml, the file with the fitted values) and
        fit.png there, as ``kalcal fit --out`` (one set).
    topic : str, optional
        A model file's ``--data`` that is a ROS bag or ULog: the topic its [data] table reads (``--topic``;
        default: the one its ``TOPIC.FIELD`` column names name). Refused for a built-in scenario.

    Returns
    -------
    FitResult
        With ``params``, ``bse``, ``conf_int()``, ``llf``, ``aic``, ``bic``, ``nobs``, ``summary()`` and
        ``save(out)``; its ``settings`` go straight back into :func:`kalcal.calibrate` and
        :func:`kalcal.verify` (``settings=fit.settings``).
    """
    from kalcal.api._scenario import resolve
    from kalcal.errors import KalcalError
    from kalcal.fitting.run import FitOptions
    from kalcal.scenarios import log_defaults

    if not 0.0 < confidence < 1.0:
        raise KalcalError(f"confidence=: expected a number in (0, 1), got {confidence!r}")  # kalcal fit has no --confidence
    from kalcal.fitting.bootstrap import whole_number

    if bootstrap is True:  # a bool is no count: True would otherwise run as B = 1
        raise KalcalError("--bootstrap: expected a number of replicates (B >= 39 at 95%; 0 or False: none), got True")
    bootstrap = 0 if bootstrap is False else bootstrap
    if not whole_number(bootstrap) or bootstrap < 0:  # nan, inf, 40.5, "40", -1: one line, not int()'s error
        raise KalcalError(f"--bootstrap: expected 0 (none) or a positive whole number of replicates, got {bootstrap!r}")
    unused = [flag for flag, value in (("--seed", seed), ("--threads", threads), ("--workers", workers),
                                       ("--scheduler", scheduler)) if value is not None]
    if unused and not bootstrap:  # each sets the bootstrap's run alone: a fit without one would ignore it
        raise KalcalError(f"{', '.join(unused)}: only with --bootstrap (the bootstrap's seed and where its refits run)")
    seed = 0 if seed is None else seed
    if bootstrap:
        from kalcal.fitting.bootstrap import check_replicates

        from kalcal.montecarlo.engine import check_seed

        check_replicates(bootstrap, confidence)  # before the fit: too few replicates for the interval's level
        check_seed(seed)
    if threads is not None and threads < 1:
        raise KalcalError(f"--threads: expected a positive number, got {threads}")
    import contextlib

    from kalcal.montecarlo.distributed import dask_client

    options = FitOptions(free=_free(free), profile=profile, confidence=confidence, imu_columns=imu_columns,
                         gps_columns=gps_columns, init=init, gate=gate, reference=reference, sensor=sensor,
                         bootstrap=int(bootstrap), seed=seed, threads=threads)
    model = resolve(scenario, settings, config, defaults=log_defaults(scenario), models=True)  # a model file too
    from kalcal.scenarios.protocol import require

    require(model, "fit")  # a command the scenario lacks: one line naming it and why
    from kalcal.api._scenario import command_label, with_topic

    logs = with_topic(model, {"imu": imu, "gps": gps, "data": data}, topic)
    cluster = (dask_client(workers, scheduler) if bootstrap and client is None and (workers is not None or scheduler is not None)
               else contextlib.nullcontext(client))
    if out is None:
        with cluster as used:
            # the FitResult the scenario's fit made; its save() writes its files
            return model.fit(logs, dataclasses.replace(options, client=used))
    from kalcal.fitting.run import save_fit
    from kalcal.io.outputs import inputs_of, mark_inputs, run_outputs

    from kalcal.fitting.run import BOOTSTRAP_NAME

    names = (*model.output_names("fit"), *((BOOTSTRAP_NAME,) if bootstrap else ()))
    files = [value for key, value in logs.items() if key != "topic" and isinstance(value, (str, Path))]
    with run_outputs(out, command_label("fit", model), names=names, protect=[*files, *inputs_of(model)]) as staging:
        with cluster as used:
            result = model.fit(logs, dataclasses.replace(options, client=used))
        save_fit(result, staging)
    # the result as saved, still knowing the logs it was read from (a later save never removes them)
    return mark_inputs(dataclasses.replace(result, paths={name: Path(out) / name for name in names}), *inputs_of(result))
