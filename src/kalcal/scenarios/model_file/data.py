"""A model file's ``[data]`` table and the binding of the file to a log: the model of that log, row by row.

The ``[data]`` table says how a log's columns feed the model, one row per model step of ``sample_period``::

    [data]
    time = "t"                      # optional: the time column (s); absent, row j is at j * sample_period
    measurements = ["z"]            # p columns, in the order of h's rows (an empty or NaN cell: not measured)
    inputs = ["accel"]              # m columns, the known inputs u_j (beside a top-level b, (d, m)); finite
    stds = ["z_std"]                # optional, p entries: a std column, or "" for the file's v
    step_tolerance = 0.01           # a time step may differ from sample_period by this fraction of it

:func:`bind` reads the log through :mod:`kalcal.io.logs` (CSV, compressed CSV, Parquet, a ROS bag's or a
ULog's topic, whose columns are ``TOPIC.FIELD`` and whose time column is ``time``, or a DataFrame) and
returns a :class:`BoundModel`: the filter's :class:`~kalcal.core.timevarying.TimeVaryingModel` (and the
truth's, where the file's truth differs from its filter), z (J, p) and the times (J,). Row j's H_j is h
with each entry that names a column read from row j; V_j is v, with a std column's component scaled to
that row's std (V_j = D_j V D_j, D_j = diag(std_j / sqrt(diag V)): the correlation of v is held); u_j the
inputs of row j (it drives row j -> j + 1).

:func:`step_grid` is the same container for a file read without a log: K updates on the step grid
(J = K m + 1 rows, row 0 the prior, measured at rows m, 2m, ..., Km), the model ``verify`` checks.

A bag's or ULog's topic: the file's columns name it (``/imu.linear_acceleration.x``), or, where the topic
is given (``--topic /imu``), they may name its fields alone (``linear_acceleration.x``), so that one file
reads any topic of its message type (two IMUs of one bag, each with ``--topic``): :func:`read_log`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from kalcal.core.timevarying import TimeVaryingModel
from kalcal.errors import DataError
from kalcal.models.settings import SettingError, show, to_labels, to_positive_number, to_string, unknown

if TYPE_CHECKING:
    import pandas as pd

    from kalcal.scenarios.model_file.linear import FileModel
    from kalcal.scenarios.model_file.model import CustomModelScenario

__all__ = ["DATA_KEYS", "DEFAULT_STEP_TOLERANCE", "BoundModel", "DataTable", "bind", "data_table", "step_grid"]

#: the keys of a [data] table
DATA_KEYS = ("time", "measurements", "inputs", "stds", "step_tolerance")
#: the largest relative departure of a time step from sample_period that a log may have, by default
DEFAULT_STEP_TOLERANCE = 0.01


@dataclass(frozen=True)
class DataTable:
    """A model file's ``[data]`` table (the settings section ``data``).

    Attributes
    ----------
    time : str
        The time column (s); "" for none (row j at j * sample_period).
    measurements : tuple of str
        p columns, in the order of h's rows.
    inputs : tuple of str
        m columns, the known inputs (the columns of b).
    stds : tuple of str
        () or p entries: a column of the component's std (in the measurement's unit), "" for v's.
    step_tolerance : float
        The largest |dt - T| / T a log's time step may have (dimensionless, 0 < tol < 0.5).
    """

    time: str = ""
    measurements: tuple[str, ...] = ()
    inputs: tuple[str, ...] = ()
    stds: tuple[str, ...] = ()
    step_tolerance: float = DEFAULT_STEP_TOLERANCE

    def __post_init__(self) -> None:
        for key in ("measurements", "inputs", "stds"):
            object.__setattr__(self, key, tuple(getattr(self, key)))
        object.__setattr__(self, "time", str(self.time or ""))
        object.__setattr__(self, "step_tolerance", float(self.step_tolerance))

    @property
    def columns(self) -> tuple[str, ...]:
        """Every column the table names (time, measurements, inputs, stds), each once."""
        return tuple(dict.fromkeys(c for c in (self.time, *self.measurements, *self.inputs, *self.stds) if c))


def _names(key: str, value: Any, count: int | None = None, of: str = "", empty: bool = False) -> tuple[str, ...]:
    names = to_labels(key, value, count, of)
    for name in names:
        if not name.strip() and not empty:
            raise SettingError(key, "non-empty column names", show(list(names)))
    return names


def data_table(table: Any, d: int, p: int, m: int) -> DataTable:
    """A ``[data]`` table -> :class:`DataTable`, checked against the model's p measurements and m inputs
    (``m`` is b's columns, 0 without b); errors keyed ``data.KEY`` (``b`` where only one of b and
    ``data.inputs`` is given)."""
    if not isinstance(table, dict):
        raise SettingError("data", "a [data] table", show(table))
    for key in table:
        if key not in DATA_KEYS:
            raise unknown(f"data.{key}", f"a key of [data] ({', '.join(DATA_KEYS)})")
    if "measurements" not in table:
        raise SettingError("data.measurements", f"{p} column names, one per row of h", "nothing (a required key)")
    measurements = _names("data.measurements", table["measurements"], p, "row of h")
    inputs = _names("data.inputs", table["inputs"]) if "inputs" in table else ()
    if len(inputs) != m:
        if m and not inputs:
            raise SettingError("data.inputs", f"{m} column names, one per column of b", "nothing (b needs its inputs)")
        if not m:
            raise SettingError("b", f"a ({d}, {len(inputs)}) matrix beside data.inputs", "nothing (inputs need their b)")
        raise SettingError("data.inputs", f"{m} entries (one per column of b)", f"{len(inputs)}: {show(list(inputs))}")
    stds = _names("data.stds", table["stds"], p, "measurement", empty=True) if "stds" in table else ()
    time = to_string("data.time", table["time"]) if "time" in table else ""
    if "time" in table and not time.strip():
        raise SettingError("data.time", "a column name (leave time out for row j at j * sample_period)", show(time))
    tolerance = to_positive_number("data.step_tolerance", table.get("step_tolerance", DEFAULT_STEP_TOLERANCE))
    if tolerance >= 0.5:
        raise SettingError("data.step_tolerance", "a fraction of sample_period below 0.5", show(tolerance))
    return DataTable(time, measurements, inputs, stds, tolerance)


@dataclass(frozen=True)
class BoundModel:
    """A model file bound to one log: what the filter, the smoother and the likelihood run over.

    Attributes
    ----------
    filter : TimeVaryingModel
        The filter's model of the log, J rows.
    truth : TimeVaryingModel or None
        The truth's, where the file's truth differs from its filter (its own n states with a map).
    truth_map : ndarray, shape (d, n), or None
        The map of a truth with states of its own (the filter's states are map @ x_truth).
    z : ndarray, shape (J, p)
        The measurements (NaN: not measured).
    times : ndarray, shape (J,)
        Each row's time, s (the log's time column, or j * sample_period).
    source : str
        The log's name in messages (its path, ``FILE topic TOPIC``, ``<data DataFrame>``).
    table : DataTable
        The columns read (the file's ``[data]`` table).
    state_names, measurement_names : tuple of str
        The file's labels, length d and p.
    """

    filter: TimeVaryingModel
    truth: TimeVaryingModel | None
    truth_map: np.ndarray | None
    z: np.ndarray
    times: np.ndarray
    source: str
    table: DataTable
    state_names: tuple[str, ...]
    measurement_names: tuple[str, ...]


def _diffuse_flags(scenario: CustomModelScenario) -> np.ndarray:
    names = scenario.model.state_names
    return np.array([name in scenario.filter.diffuse for name in names], dtype=bool)


def _time_varying(
    model: FileModel, h: np.ndarray, v: np.ndarray, u: np.ndarray, times: np.ndarray, diffuse: np.ndarray | None
) -> TimeVaryingModel:
    d = model.state_dim
    return TimeVaryingModel(
        phi=model.phi, gamma=model.gamma, w=model.w, b=model.b, x0=model.x0, m0=model.m0, h=h, v=v, u=u,
        diffuse=np.zeros(d, dtype=bool) if diffuse is None else diffuse, sample_period=model.sample_period, times=times,
    )  # fmt: skip


def _rows(model: FileModel, columns: dict[str, np.ndarray], count: int) -> np.ndarray:
    """H_j for every row: h with each named entry read from its column, shape (J, p, d)."""
    h = np.broadcast_to(model.h, (count, *model.h.shape)).copy()
    for i, row in enumerate(model.h_columns):
        for k, name in enumerate(row):
            if name:
                h[:, i, k] = columns[name]
    return h


def _truth_differs(scenario: CustomModelScenario) -> bool:
    f, t = scenario.filter, scenario.truth
    if scenario.truth_map is not None:
        return True
    return bool(scenario.differing()) or not np.array_equal(f.b, t.b) or f.h_columns != t.h_columns


def read_log(log: str | Path | pd.DataFrame, topic: str | None, columns: tuple[str, ...]) -> pd.DataFrame:
    """The log as :func:`kalcal.io.logs.read_table` reads it; with ``topic`` given, each ``TOPIC.FIELD``
    column of that topic is also under ``FIELD`` (where the log has no column of that name), so that a
    file's columns may name a field without its topic.

    Raises
    ------
    DataError
        read_table's one line (a topic for a CSV, Parquet or DataFrame log is refused there).
    """
    from kalcal.io.logs import read_table

    if topic is None:
        return read_table(log, "data", columns=columns)
    # the topic is given: a column naming a field alone is not a TOPIC.FIELD naming another topic
    frame = read_table(log, "data", topic=topic)
    prefix = f"{topic}."
    fields = {c[len(prefix):]: c for c in frame.columns if c.startswith(prefix) and c[len(prefix):] not in frame.columns}
    wanted = {field: frame[column] for field, column in fields.items() if field in columns}
    if not wanted:
        return frame
    attrs = dict(frame.attrs)
    frame = frame.assign(**wanted)
    frame.attrs.update(attrs)
    return frame


def bind(scenario: CustomModelScenario, log: str | Path | pd.DataFrame, *, topic: str | None = None) -> BoundModel:
    """The model file ``scenario`` over one log: its models row by row, z and the times.

    Parameters
    ----------
    scenario : CustomModelScenario
        A model file with a ``[data]`` table.
    log : path or DataFrame
        Any log :func:`kalcal.io.logs.read_table` reads; one row per model step.
    topic : str, optional
        A ROS bag's or ULog's topic (default: the one the ``TOPIC.FIELD`` column names name).

    Raises
    ------
    ConfigError
        The file has no ``[data]`` table.
    DataError
        One line naming the log (and topic): a missing column (with the columns it has), a cell that is
        not a number, an infinite value, a NaN in the time or an input column (named by row), time not
        increasing, a step off ``sample_period`` beyond ``step_tolerance`` (named by row and step), a std
        that is not > 0 where its component is measured.
    """
    from kalcal.io.logs import numeric_columns, read_table, require_increasing, source_name

    table = scenario.data
    if table is None:
        raise SettingError("data", "a [data] table naming the log's columns to bind the file to a log", "none", scenario.model.file)
    f, t = scenario.filter, scenario.truth
    named = tuple(dict.fromkeys((*f.data_columns, *t.data_columns)))
    wanted = tuple(dict.fromkeys((*table.columns, *named)))
    frame = read_log(log, topic, wanted)
    name = source_name(log, "data", frame)
    nan_ok = (*table.measurements, *(s for s in table.stds if s), *named)
    values = numeric_columns(frame, name, wanted, allow_nan=[c for c in nan_ok if c not in (table.time, *table.inputs)])
    count = len(frame)
    period = f.sample_period
    if table.time:
        times = values[table.time]
        require_increasing(times, name, table.time)
        off = np.abs(np.diff(times) - period) > table.step_tolerance * period
        if np.any(off):
            j = int(np.argmax(off))
            raise DataError(
                f"{name}: row {j + 2}, column {table.time!r}: time step {times[j + 1] - times[j]:.9g} s from row "
                f"{j + 1} is off sample_period {period:g} s by more than step_tolerance {table.step_tolerance:g} "
                f"(a fraction of it): the model steps once per row"
            )
    else:
        times = np.arange(count) * period
    z = np.column_stack([values[c] for c in table.measurements]) if table.measurements else np.zeros((count, 0))
    u = np.column_stack([values[c] for c in table.inputs]) if table.inputs else np.zeros((count, 0))
    scale = np.ones((count, f.measurement_dim))
    base = np.sqrt(np.diag(f.v))
    for i, column in enumerate(table.stds):
        if not column:
            continue
        std = values[column]
        bad = ~(std > 0) & (np.isfinite(z[:, i]) | np.isfinite(std))  # NaN is allowed only where z_i is NaN
        if np.any(bad):
            j = int(np.argmax(bad))
            raise DataError(
                f"{name}: row {j + 1}, column {column!r}: std {float(std[j])!r}, expected a positive number "
                f"(the std of measurement {table.measurements[i]!r})"
            )
        scale[:, i] = np.where(np.isfinite(std), std / base[i], 1.0)

    def noise(model: FileModel) -> np.ndarray:
        # V_j = D_j V D_j: the row's std for a std column, the correlation of v held
        return scale[:, :, None] * model.v[None, :, :] * scale[:, None, :]

    def over(model: FileModel, diffuse: np.ndarray | None) -> TimeVaryingModel:
        if model.input_dim != u.shape[1]:
            raise SettingError("truth.b", f"{u.shape[1]} columns, one per input of [data]", f"shape {model.b.shape}", scenario.model.file)
        return _time_varying(model, _rows(model, values, count), noise(model), u, times, diffuse)

    try:
        filter_model = over(f, _diffuse_flags(scenario))
        truth_model = over(t, None) if _truth_differs(scenario) else None
    except SettingError as exc:
        raise DataError(f"{name}: {exc}") from None  # a row the log gives that the model cannot take (V_j)
    return BoundModel(
        filter=filter_model, truth=truth_model, truth_map=scenario.truth_map, z=z, times=times, source=name,
        table=table, state_names=scenario.model.state_names, measurement_names=scenario.model.measurement_names,
    )  # fmt: skip


def step_grid(scenario: CustomModelScenario) -> tuple[TimeVaryingModel, TimeVaryingModel | None]:
    """A file's model without a log: K = ``updates`` measurement updates on the step grid.

    J = K m + 1 rows (m = ``steps_per_update``), row j at j * sample_period; row 0 holds the prior and is
    not measured, rows m, 2m, ..., Km are (H_j = h, V_j = v), the others are not (H_j NaN): the model
    that ``verify``'s fixed-gain filter runs (first fix after m steps). Known inputs are u_j = 0: with a
    truth that the inputs move as the filter believes (no b, phi or h of its own, or, with a map, M B_t = B,
    M Phi_t = Phi M, H_t = H M), the filter's error does not depend on u; any other truth is refused
    without a log (:meth:`~kalcal.scenarios.model_file.model.CustomModelScenario.without_log`).

    Returns
    -------
    (filter, truth)
        The truth's model is None where it is the filter's.

    Raises
    ------
    ConfigError
        One line: the file lacks ``updates``, or its h names data columns (the rows come from a log).
    """
    f, t, info = scenario.filter, scenario.truth, scenario.model
    if info.updates is None:
        raise SettingError("updates", "a positive integer (the model without a log runs that many updates)", "nothing", info.file)
    if f.h_columns or t.h_columns:
        raise SettingError("h", "numbers (the rows of a model without a log)", f"data columns {', '.join(f.data_columns or t.data_columns)}", info.file)
    m, count = f.steps_per_update, info.updates * f.steps_per_update + 1
    measured = (np.arange(count) % m == 0) & (np.arange(count) > 0)
    times = np.arange(count) * f.sample_period

    def over(model: FileModel, diffuse: np.ndarray | None) -> TimeVaryingModel:
        h = np.where(measured[:, None, None], model.h[None], np.nan)
        v = np.broadcast_to(model.v, (count, *model.v.shape))
        return _time_varying(model, h, v, np.zeros((count, model.input_dim)), times, diffuse)

    return over(f, _diffuse_flags(scenario)), (over(t, None) if _truth_differs(scenario) else None)
