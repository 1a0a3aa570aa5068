"""``kalcal simulate MODEL.toml --data LOG``: a log in the file's ``[data]`` layout, its measurements drawn.

The given log supplies what the file takes from data and does not model: the time column, the known
inputs, the data columns h names (the regressors), the std columns, and which rows measure which
component. The file's truth (its ``[truth]``, or its filter where it has none) is then drawn once, row
by row, as the binding reads the log (:func:`kalcal.scenarios.model_file.data.bind`)::

    x_0 ~ N(x0, m0),   x_{j+1} = Phi x_j + B u_j + Gamma w_j,   z_j = H_j x_j + v_j,  v_j ~ N(0, V_j)

with the truth's matrices (its own states, mapped to the filter's by its ``map``), H_j and V_j the rows the
given log makes (an h entry naming a column read from it, a std column scaling v). A measurement is
written where the given log has one and NaN where it has none (the same missing pattern; also NaN where
the row of h names an empty data column). The simulated log holds the time column, the measurement
columns, the std columns, the input columns and the data columns h names (those copied from the given
log, its other columns left out), then the true states in the filter's coordinates as ``<state>_true``
columns (the state's unit; at each row, before that row's measurement noise): ``data.csv``, which
``kalcal calibrate MODEL.toml --data data.csv`` reads back as the filter expects. ``truth.json`` says
what was drawn from what.

Randomness is the seed's alone (``numpy.random.default_rng(seed)``), drawn in a fixed order whatever the
missing pattern: the prior's r0 standard normals (r0 the rank of m0), then (J - 1, q') for the process
noise (q' the rank of w), then (J, p) for the measurement noise. The same seed and log give the same
simulated log.

A filter that starts diffuse has no distribution to draw its first state from: such a file needs a
``[truth]`` m0 (the world's proper prior) to be simulated, and is refused without one.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from kalcal.errors import ConfigError

if TYPE_CHECKING:
    from kalcal.core.timevarying import TimeVaryingModel
    from kalcal.results.simulation import SimulationResult
    from kalcal.scenarios.model_file.model import CustomModelScenario

__all__ = ["OUTPUT_NAMES", "TRUE_SUFFIX", "draw", "simulate_logs", "simulate_model_file"]

#: the files a model file's simulation writes
OUTPUT_NAMES = ("data.csv", "truth.json")
#: the true states' columns are the filter's state names with this suffix
TRUE_SUFFIX = "_true"


def draw(model: TimeVaryingModel, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """One realization of ``model``'s states and measurements at every row (the module docstring's order).

    Parameters
    ----------
    model : TimeVaryingModel
        A model with no diffuse state (its m0 proper, possibly singular).
    rng : numpy.random.Generator

    Returns
    -------
    x : ndarray, shape (J, n)
        The states at each row (the model's units).
    z : ndarray, shape (J, p)
        H_j x_j + v_j; NaN where H_j's row is NaN (an empty data column).
    """
    from kalcal.linalg import psd_factor

    n, rows = model.state_dim, model.steps
    prior = psd_factor(model.m0)
    x0 = model.x0 + prior @ rng.standard_normal(prior.shape[1])
    noise = psd_factor(model.w)
    w = rng.standard_normal((max(rows - 1, 0), noise.shape[1])) @ noise.T
    drive = w @ model.gamma.T
    if model.b.size:
        drive = drive + model.u[:-1] @ model.b.T
    x = np.empty((rows, n))
    x[0] = x0
    for j in range(rows - 1):  # J small matrix-vector products: the recursion itself, ~1 us a row
        x[j + 1] = model.phi @ x[j] + drive[j]
    lower = np.linalg.cholesky(model.v)  # positive definite at every row (TimeVaryingModel checks it)
    v = np.einsum("jab,jb->ja", lower, rng.standard_normal((rows, model.measurement_dim)))
    z = np.einsum("jpd,jd->jp", model.h, x) + v
    return x, z


def simulate_model_file(scenario: CustomModelScenario, log: Any, seed: int, *, topic: str | None = None) -> SimulationResult:
    """Simulate the file over the rows of ``log`` (the module docstring); nothing is written.

    Parameters
    ----------
    scenario : CustomModelScenario
        A model file with a ``[data]`` table.
    log : path or DataFrame
        The log whose times, inputs, data columns, stds and missing pattern are kept (read and checked as
        ``calibrate`` reads it).
    seed : int
        The random generator's seed.
    topic : str, optional
        A bag's or ULog's topic.

    Returns
    -------
    SimulationResult
        ``logs["data"]`` (data.csv) and ``truth`` (truth.json).

    Raises
    ------
    ConfigError, DataError
        One line: a file without [data], a diffuse filter without a [truth] m0, a column the simulated log
        would hold twice, or the log's own faults (as calibrate refuses them).
    """
    import pandas as pd

    from kalcal.io.logs import numeric_columns
    from kalcal.scenarios.model_file.data import read_log
    from kalcal.models.config import section_values
    from kalcal.results.simulation import SimulationResult

    info, table = scenario.model, scenario.data
    bound = scenario.bind(log, topic=topic)  # every check of the log, as calibrate makes them
    truth = bound.truth if bound.truth is not None else bound.filter
    if truth.diffuse.any():
        diffuse = ", ".join(name for name, flag in zip(info.state_names, truth.diffuse) if flag)
        raise ConfigError(
            f"{info.file}: its filter starts diffuse in {diffuse} and it has no [truth] m0: give [truth] m0 (the "
            "world's proper prior) to simulate it"
        )
    named = tuple(dict.fromkeys((*scenario.filter.data_columns, *scenario.truth.data_columns)))
    copied = tuple(c for c in dict.fromkeys((*table.columns, *named)) if c not in table.measurements)
    read = (table.time, *table.inputs, *table.stds, *named)
    states = tuple(f"{name}{TRUE_SUFFIX}" for name in info.state_names)
    drawn = (*table.measurements, *states)
    for column in drawn:
        if column in read or drawn.count(column) > 1:
            raise ConfigError(f"{info.file}: the simulated log would hold the column {column!r} twice (a measurement "
                              "column that is also read as a time, input, std or h column, or a state's true column)")
    frame = read_log(log, topic, (*table.columns, *named))
    values = numeric_columns(frame, bound.source, copied, allow_nan=copied)  # checked by bind already
    x, z = draw(truth, np.random.default_rng(seed))
    z[~np.isfinite(bound.z)] = np.nan  # the given log's missing pattern
    filter_states = x if bound.truth_map is None else x @ bound.truth_map.T
    order = [c for c in dict.fromkeys((*table.columns, *named))]
    columns: dict[str, np.ndarray] = {}
    for column in order:
        if column in table.measurements:
            columns[column] = z[:, table.measurements.index(column)]
        else:
            columns[column] = values[column]
    columns.update({name: filter_states[:, i] for i, name in enumerate(states)})
    data = pd.DataFrame(columns)
    record = {
        "scenario": scenario.NAME,
        "model": info.name,
        "file": str(info.file),
        "seed": int(seed),
        "data": bound.source,
        "rows": int(bound.z.shape[0]),
        "measurements": int(np.count_nonzero(np.isfinite(z))),
        "drawn_from": "the file's [truth]" if bound.truth is not None else "the file's filter model (it has no [truth])",
        "true_states": list(states),
        "copied": list(copied),
        "settings": section_values(scenario),
    }
    return SimulationResult(scenario.NAME, {"data": data}, record, OUTPUT_NAMES)


def simulate_logs(scenario: CustomModelScenario, seed: int, logs: dict[str, Any] | None) -> SimulationResult:
    """:meth:`CustomModelScenario.simulate`: the ``data`` log required (the file draws over its rows)."""
    from kalcal.errors import KalcalError
    from kalcal.scenarios.protocol import require

    require(scenario, "simulate")
    logs = logs or {}
    if logs.get("imu") is not None or logs.get("gps") is not None:
        raise KalcalError(f"--imu/--gps: not used by {scenario.label} (it reads --data)")
    if logs.get("data") is None:
        raise KalcalError(
            f"--data: required to simulate {scenario.label} (a log whose times, inputs and data columns the "
            "simulated log keeps)"
        )
    return simulate_model_file(scenario, logs["data"], seed, topic=logs.get("topic"))
