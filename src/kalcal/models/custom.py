"""A user's own linear Gaussian model, read from a TOML *model file*, as a verification scenario.

The file describes the filter's model (top-level keys) and, optionally, a truth that departs from it
(a ``[truth]`` table holding any subset of the matrices; the rest are the filter's)::

    name = "constant-velocity"        # optional; default: the file's stem
    sample_period = 0.1               # s per model step; optional, default 1
    steps_per_update = 10             # model steps between two measurement updates (integer >= 1)
    updates = 30                      # measurement updates to verify (integer >= 1)
    phi   = [[1.0, 0.1], [0.0, 1.0]]  # (d, d) transition over one step
    gamma = [[0.005], [0.1]]          # (d, q) process-noise input
    h     = [[1.0, 0.0]]              # (p, d) measurement matrix
    w     = [[0.04]]                  # (q, q) process-noise covariance per step
    v     = [[4.0]]                   # (p, p) measurement-noise covariance (positive definite)
    x0    = [0.0, 10.0]               # (d,) prior mean at step 0
    m0    = [[25.0, 0.0], [0.0, 1.0]] # (d, d) prior covariance at step 0
    state_names = ["position", "velocity"]   # optional (default x1..xd), and
    state_units = ["m", "m/s"]               # state_units, measurement_names (z1..zp),
    measurement_names = ["position"]         # measurement_units (default: none)
    measurement_units = ["m"]

    [truth]                           # optional: what the world does where it differs
    w = [[0.16]]

The model is the one of :class:`~kalcal.models.linear.LinearGaussianModel`: the first measurement is
taken after ``steps_per_update`` steps, update k (k = 1..updates) at t_k = k * steps_per_update *
sample_period. The truth shares the filter's timing and dimensions (d states, p measurements; its
noise input may have another q).

Every problem is a :class:`~kalcal.errors.ConfigError` of one line that starts with the file's name and
names the key: unknown and missing keys, wrong types, a matrix whose shape does not fit (through
LinearGaussianModel's own validation), a covariance that is not symmetric positive semi-definite.

In a run's ``summary.json`` the scenario's settings are the sections ``model`` (name, file, updates,
names, units), ``filter`` and ``truth`` (each model's matrices, steps_per_update, sample_period): enough
to rebuild the scenario without the file (:meth:`CustomModelScenario.from_settings`), and the keys that
``--set`` accepts (:func:`load_model_file`).
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from kalcal.errors import ConfigError
from kalcal.models.accel_gps import AccelGpsScenario
from kalcal.models.config import parse_assignments
from kalcal.models.linear import LinearGaussianModel
from kalcal.models.scale_bias import ScaleBiasScenario

#: The model's arrays, in the order of LinearGaussianModel; all but x0 are matrices.
MODEL_KEYS = ("phi", "gamma", "h", "w", "v", "x0", "m0")
_REQUIRED = ("steps_per_update", "updates", *MODEL_KEYS)
_NAME_KEYS = ("state_names", "state_units", "measurement_names", "measurement_units")
_TOP_KEYS = ("name", "sample_period", *_REQUIRED, *_NAME_KEYS)
#: ``--set`` keys by section, as the run's summary.json lists the settings.
_SET_KEYS = {
    "model": ("name", "updates", *_NAME_KEYS),
    "filter": (*MODEL_KEYS, "steps_per_update", "sample_period"),
    "truth": MODEL_KEYS,
}
_RESERVED_NAMES = (AccelGpsScenario.NAME, ScaleBiasScenario.NAME)


def is_model_file(scenario: str) -> bool:
    """Whether a SCENARIO argument names a model file (it ends in ``.toml``) rather than a built-in."""
    return str(scenario).lower().endswith(".toml")


def is_custom_settings(settings: Mapping[str, Any]) -> bool:
    """Whether a summary's ``settings`` are those of a custom model (sections model, filter, truth)."""
    return set(settings) == {"model", "filter", "truth"}


@dataclass(frozen=True)
class CustomModelInfo:
    """What labels a custom model's results (section ``model``).

    name : the scenario's name in outputs; file : the model file as given (for the record);
    updates : K, measurement updates to verify; state_names, state_units : length d;
    measurement_names, measurement_units : length p. Units are SI labels ("" for none).
    """

    name: str
    file: str
    updates: int
    state_names: tuple[str, ...]
    state_units: tuple[str, ...]
    measurement_names: tuple[str, ...]
    measurement_units: tuple[str, ...]


@dataclass(frozen=True)
class CustomModelScenario:
    """A user's linear Gaussian model: the filter's model, the truth's, and the labels.

    Attributes
    ----------
    model : CustomModelInfo
    filter : LinearGaussianModel
        What the filter believes (the file's top-level matrices).
    truth : LinearGaussianModel
        What the world does (the ``[truth]`` table over the filter's matrices); same d, p,
        steps_per_update and sample_period as the filter.
    """

    NAME: ClassVar[str] = "custom"

    model: CustomModelInfo
    filter: LinearGaussianModel
    truth: LinearGaussianModel

    def __post_init__(self) -> None:
        f, t, info = self.filter, self.truth, self.model
        d, p = f.state_dim, f.measurement_dim
        if t.phi.shape != f.phi.shape:
            raise ConfigError(f"truth.phi: expected shape {f.phi.shape} like the filter's phi, got {t.phi.shape}")
        if t.h.shape != f.h.shape:
            raise ConfigError(f"truth.h: expected shape {f.h.shape} like the filter's h, got {t.h.shape}")
        if (t.steps_per_update, t.sample_period) != (f.steps_per_update, f.sample_period):
            raise ConfigError("truth: steps_per_update and sample_period must be the filter's")
        if not (isinstance(info.updates, int) and not isinstance(info.updates, bool) and info.updates >= 1):
            raise ConfigError(f"updates: expected a positive integer, got {info.updates!r}")
        if not info.name.strip():
            raise ConfigError(f"name: expected a non-empty name, got {info.name!r}")
        if info.name in _RESERVED_NAMES:
            raise ConfigError(f"name: {info.name!r} is a built-in scenario's name; choose another")
        for key, count in (("state_names", d), ("state_units", d), ("measurement_names", p), ("measurement_units", p)):
            values = getattr(info, key)
            if len(values) != count:
                raise ConfigError(f"{key}: expected {count} entries, got {len(values)}")

    @property
    def update_times(self) -> np.ndarray:
        """t_k = k * steps_per_update * sample_period for k = 1..K, s, shape (K,)."""
        return np.arange(1, self.model.updates + 1) * self.filter.update_period

    def differing(self) -> tuple[str, ...]:
        """The matrices in which the truth departs from the filter, in MODEL_KEYS order."""
        return tuple(k for k in MODEL_KEYS if not np.array_equal(getattr(self.filter, k), getattr(self.truth, k)))

    @classmethod
    def from_settings(cls, settings: Mapping[str, Mapping[str, Any]]) -> CustomModelScenario:
        """Rebuild the scenario from a summary's ``settings`` (sections model, filter, truth)."""
        try:
            info = dict(settings["model"])
            for key in _NAME_KEYS:
                info[key] = tuple(info[key])
            return cls(
                CustomModelInfo(**info),
                LinearGaussianModel(**settings["filter"]),
                LinearGaussianModel(**settings["truth"]),
            )
        except (KeyError, TypeError) as exc:
            raise ConfigError(f"custom model settings are incomplete or malformed ({exc})") from None


# --- reading model files -------------------------------------------------------------------------


def load_model_file(
    path: str | Path, assignments: Iterable[str] = (), *, config: str | Path | None = None
) -> CustomModelScenario:
    """Read, override and validate a model file.

    Parameters
    ----------
    path : path
        The TOML model file.
    assignments : iterable of str
        ``--set`` overrides ``section.key=value`` with a TOML value, addressed as the run's summary
        lists the settings: ``filter.KEY`` (phi, gamma, h, w, v, x0, m0, steps_per_update,
        sample_period: the file's top-level keys), ``truth.KEY`` (the matrices of ``[truth]``) and
        ``model.KEY`` (name, updates, the names and units). E.g. ``filter.w=[[0.01]]``, ``model.updates=60``.
        ``filter.KEY`` retunes the filter alone: where ``[truth]`` does not set KEY, the truth keeps the
        file's value (so that a sweep of a filter setting holds the world fixed).
    config : path, optional
        Must be None: a model file holds all its settings (``--config`` is for built-in scenarios).

    Raises
    ------
    ConfigError
        One line naming the file (or the --set key) and the key at fault.
    """
    path = Path(path)
    if config is not None:
        raise ConfigError(f"--config: not used with a model file ({path}); put the settings in the file or use --set")
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such model file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read the model file ({exc})") from None
    from kalcal.io.outputs import mark_inputs

    return mark_inputs(parse_model(text, str(path), assignments), path)  # a job given it never removes the file


def parse_model(text: str, source: str, assignments: Iterable[str] = ()) -> CustomModelScenario:
    """A model file's text -> the validated scenario; ``source`` names the file in errors and outputs."""
    try:
        document = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{source}: not valid TOML ({exc})") from None
    overrides = parse_assignments(assignments)
    _apply_overrides(document, overrides)
    label = f"{source} (with --set {', '.join(overrides)})" if overrides else source
    try:
        return _build(document, source)
    except ConfigError as exc:
        raise ConfigError(f"{label}: {exc}") from None


def _toml_value(key: str, text: str) -> Any:
    try:
        return tomllib.loads(f"value = {text}")["value"]
    except tomllib.TOMLDecodeError:
        if key == "model.name":
            return text  # a bare name needs no quotes
        raise ConfigError(f"--set {key}: expected a TOML value (e.g. [[0.01]], 60, 0.1), got {text!r}") from None


def _apply_overrides(document: dict[str, Any], overrides: Mapping[str, str]) -> None:
    for key, text in overrides.items():
        section, _, name = key.partition(".")
        if name not in _SET_KEYS.get(section, ()):
            known = "; ".join(f"{s}.{{{', '.join(keys)}}}" for s, keys in _SET_KEYS.items())
            raise ConfigError(f"unknown setting {key!r} for a model file (known: {known})")
        value = _toml_value(key, text)
        if section in ("truth", "filter") and name in MODEL_KEYS:
            table = document.setdefault("truth", {})
            if not isinstance(table, dict):
                raise ConfigError(f"--set {key}: the file's 'truth' is not a [truth] table")
            if section == "truth":
                table[name] = value
                continue
            # filter.KEY retunes the filter only: the truth keeps the file's value (as for built-in scenarios)
            if name in document and name not in table:
                table[name] = document[name]
        document[name] = value


def _type_name(value: Any) -> str:
    names = {bool: "a boolean", str: "a string", dict: "a table", list: "an array"}
    return names.get(type(value), type(value).__name__)


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _matrix(key: str, value: Any) -> np.ndarray:
    example = "[[1.0, 0.0], [0.0, 1.0]]"
    if not isinstance(value, list) or not all(isinstance(row, list) for row in value):
        raise ConfigError(f"{key}: expected a matrix, an array of rows such as {example}, got {value!r}")
    for i, row in enumerate(value):
        for item in row:
            if not _is_number(item):
                raise ConfigError(f"{key}: expected numbers, got {item!r} ({_type_name(item)}) in row {i + 1}")
    lengths = sorted({len(row) for row in value})
    if not lengths or lengths == [0]:
        raise ConfigError(f"{key}: expected a non-empty matrix such as {example}, got {value!r}")
    if len(lengths) > 1:
        raise ConfigError(f"{key}: rows of different lengths ({', '.join(map(str, lengths))})")
    return np.array(value, dtype=float)


def _vector(key: str, value: Any) -> np.ndarray:
    if not isinstance(value, list):
        raise ConfigError(f"{key}: expected an array of numbers such as [0.0, 1.0], got {value!r}")
    for item in value:
        if not _is_number(item):
            raise ConfigError(f"{key}: expected numbers, got {item!r} ({_type_name(item)})")
    return np.array(value, dtype=float)


def _array(key: str, value: Any) -> np.ndarray:
    return _vector(key, value) if key.endswith("x0") else _matrix(key, value)


def _integer(key: str, value: Any) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or value < 1:
        raise ConfigError(f"{key}: expected a positive integer, got {value!r}")
    return value


def _labels(key: str, value: Any) -> tuple[str, ...]:
    if not isinstance(value, list) or not all(isinstance(item, str) for item in value):
        raise ConfigError(f"{key}: expected an array of strings, got {value!r}")
    return tuple(value)


def _build(document: dict[str, Any], source: str) -> CustomModelScenario:
    unknown = [key for key in document if key not in _TOP_KEYS and key != "truth"]
    if unknown:
        raise ConfigError(f"unknown key {unknown[0]!r} (known: {', '.join(_TOP_KEYS)} and a [truth] table)")
    truth = document.get("truth", {})
    if not isinstance(truth, dict):
        raise ConfigError(f"truth: expected a [truth] table of matrices, got {_type_name(truth)}")
    unknown = [key for key in truth if key not in MODEL_KEYS]
    if unknown:
        raise ConfigError(f"unknown key 'truth.{unknown[0]}' ([truth] takes {', '.join(MODEL_KEYS)})")
    missing = [key for key in _REQUIRED if key not in document]
    if missing:
        raise ConfigError(f"missing {', '.join(missing)}")

    steps = _integer("steps_per_update", document["steps_per_update"])
    updates = _integer("updates", document["updates"])
    period = document.get("sample_period", 1.0)
    if not _is_number(period) or not (math.isfinite(period) and period > 0):
        raise ConfigError(f"sample_period: expected a positive number of seconds, got {period!r}")
    name = document.get("name", Path(source).stem)
    if not isinstance(name, str):
        raise ConfigError(f"name: expected a string, got {name!r}")

    arrays = {key: _array(key, document[key]) for key in MODEL_KEYS}
    filter_model = LinearGaussianModel(**arrays, steps_per_update=steps, sample_period=float(period))
    truth_arrays = {key: _array(f"truth.{key}", truth[key]) if key in truth else arrays[key] for key in MODEL_KEYS}
    try:
        truth_model = LinearGaussianModel(**truth_arrays, steps_per_update=steps, sample_period=float(period))
    except ConfigError as exc:
        key = str(exc).partition(":")[0]
        inherited = ""
        if key in MODEL_KEYS and key not in truth:
            inherited = f" ([truth] does not set {key}, so it is the filter's)"
        raise ConfigError(f"truth.{exc}{inherited}") from None

    d, p = filter_model.state_dim, filter_model.measurement_dim
    labels = {
        "state_names": tuple(f"x{i + 1}" for i in range(d)),
        "state_units": ("",) * d,
        "measurement_names": tuple(f"z{i + 1}" for i in range(p)),
        "measurement_units": ("",) * p,
    }
    for key in _NAME_KEYS:
        if key in document:
            labels[key] = _labels(key, document[key])
    info = CustomModelInfo(name=name, file=source, updates=updates, **labels)
    return CustomModelScenario(info, filter_model, truth_model)

