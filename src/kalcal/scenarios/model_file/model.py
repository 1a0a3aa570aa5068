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

The model is the one of :class:`~kalcal.core.model.LinearGaussianModel`: the first measurement is
taken after ``steps_per_update`` steps, update k (k = 1..updates) at t_k = k * steps_per_update *
sample_period. The truth shares the filter's timing and dimensions (d states, p measurements; its
noise input may have another q), or, with a ``map``, has n states of its own (:mod:`.custom_truth`).

Every problem is a :class:`~kalcal.models.settings.SettingError` of one line,
``FILE: KEY: expected ..., got ...`` (``KEY: expected ..., got ...`` for a value given by ``--set KEY=...``):
unknown and missing keys, wrong types, a matrix whose shape does not fit (through LinearGaussianModel's
own validation), a covariance that is not symmetric positive semi-definite.

In a run's ``summary.json`` the scenario's settings are the sections ``model`` (name, file, updates,
names, units), ``filter`` and ``truth`` (each model's matrices, steps_per_update, sample_period): enough
to rebuild the scenario without the file (:meth:`CustomModelScenario.from_settings`), and the keys that
``--set`` accepts (:func:`load_model_file`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from kalcal.core.model import LinearGaussianModel
from kalcal.scenarios import scenario_names
from kalcal.scenarios.protocol import Capabilities, ScenarioDefaults
from kalcal.scenarios.model_file.truth import MAP_KEYS, MODEL_KEYS, MappedTruthModel, mapped_truth, truth_from_settings
from kalcal.models.settings import (
    SettingError,
    missing,
    parse_assignments,
    parse_toml,
    read_toml,
    show,
    to_labels,
    to_matrix,
    to_positive_integer,
    to_positive_number,
    to_string,
    to_vector,
    toml_value,
    type_name,
    unknown,
)

_REQUIRED = ("steps_per_update", "updates", *MODEL_KEYS)
_NAME_KEYS = ("state_names", "state_units", "measurement_names", "measurement_units")
_TOP_KEYS = ("name", "sample_period", *_REQUIRED, *_NAME_KEYS)
#: ``--set`` keys by section, as the run's summary.json lists the settings.
_SET_KEYS = {
    "model": ("name", "updates", *_NAME_KEYS),
    "filter": (*MODEL_KEYS, "steps_per_update", "sample_period"),
    "truth": MODEL_KEYS,
}
#: ``--set`` keys of a truth with its own states, beside those its section lists (truth.map, truth.state_names)
_TRUTH_MAP_SET_KEYS = tuple(f"truth.{key}" for key in MAP_KEYS)
_RESERVED_NAMES = scenario_names()


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
class CustomModelScenario(ScenarioDefaults):
    """A user's linear Gaussian model: the filter's model, the truth's, and the labels.

    Attributes
    ----------
    model : CustomModelInfo
    filter : LinearGaussianModel
        What the filter believes (the file's top-level matrices).
    truth : LinearGaussianModel or MappedTruthModel
        What the world does: the ``[truth]`` table over the filter's matrices (same d, p,
        steps_per_update and sample_period as the filter), or, with a ``map``, a model of its own n
        states (:mod:`kalcal.scenarios.model_file.truth`; same p and timing, map of shape (d, n)).
    """

    NAME: ClassVar[str] = "custom"
    SUMMARY: ClassVar[str] = "a linear Gaussian model read from a TOML file (docs/custom-models.md)"

    @property
    def label(self) -> str:
        """What its refusals call it: the file it was read from."""
        return f"a model file ({self.model.file})"

    @property
    def capabilities(self) -> Capabilities:
        """A linear Gaussian filter with gains fixed before any data, sampled at the update rate only (no
        per-sample engine: the file has no samples between updates) for the updates the file sets. A
        property, not a class constant: what it has depends on the file it was read from."""
        return Capabilities(
            exact_analysis=True,
            fixed_gains=True,
            engines=("exact",),
            long_run=False,
            commands=frozenset({"verify", "analyze", "report"}),
            why_not=(("--engine", "use the exact engine"), ("--long-run", "set updates in the file instead")),
        )

    # The Scenario protocol (kalcal.scenarios.protocol): each answer from this package's modules, imported
    # where asked because they import this one.

    def problem(self, form="joseph", residual_pairs: bool = True):
        """The file's filter against its truth (:func:`kalcal.scenarios.model_file.problem.custom_problem`)."""
        from kalcal.scenarios.model_file.problem import custom_problem

        return custom_problem(self, form, residual_pairs)

    def model_error_cause(self) -> str:
        """The truth's matrices that move the filter's mean error."""
        from kalcal.scenarios.model_file.problem import custom_model_error_cause

        return custom_model_error_cause(self)

    def check_settings(self, command: str) -> None:
        """Nothing to refuse: the file was checked when it was read."""

    def error_sources(self) -> list:
        """The truth's prior, process and measurement blocks."""
        from kalcal.scenarios.model_file.problem import model_error_sources

        return model_error_sources(self)

    def noise_settings(self) -> dict:
        """The truth's w, v and m0, each as factor -> the scenario with it scaled."""
        from kalcal.scenarios.model_file.problem import noise_settings

        return noise_settings(self)

    def default_long_run(self, max_updates: int) -> float:
        """0: a model file sets its own updates."""
        return 0.0

    def run_length(self) -> tuple[int, float]:
        """The file's updates: t_k = k update_period."""
        count = int(self.model.updates)
        return count, count * float(self.filter.update_period)

    def truth_is_filter(self) -> bool:
        """False: its exact analysis says whether the truth equals the filter."""
        return False

    def simulate(self, seed: int):
        from kalcal.errors import KalcalError

        raise KalcalError(f"{self.model.name}: kalcal simulate writes the built-in scenarios' logs, not a model file's")

    def output_names(self, command: str) -> tuple[str, ...]:
        from kalcal.scenarios.protocol import require

        require(self, command)
        return ()

    def calibrate(self, logs, options):
        from kalcal.scenarios.protocol import require

        require(self, "calibrate")

    def fit(self, logs, options):
        from kalcal.scenarios.protocol import require

        require(self, "fit")

    model: CustomModelInfo
    filter: LinearGaussianModel
    truth: LinearGaussianModel

    def __post_init__(self) -> None:
        f, t, info = self.filter, self.truth, self.model
        d, p = f.state_dim, f.measurement_dim
        if isinstance(t, MappedTruthModel):
            t.check_fits(d, p)
        else:
            _check_same_shapes(f, t)
        timing = (f.steps_per_update, f.sample_period)
        if (t.steps_per_update, t.sample_period) != timing:
            expected = f"the filter's steps_per_update and sample_period {timing}"
            raise SettingError("truth.steps_per_update", expected, str((t.steps_per_update, t.sample_period)))
        to_positive_integer("updates", info.updates)
        if not info.name.strip():
            raise SettingError("name", "a non-empty name", show(info.name))
        if info.name in _RESERVED_NAMES:
            expected = f"a name other than a built-in scenario's ({', '.join(_RESERVED_NAMES)})"
            raise SettingError("name", expected, show(info.name))
        for key, count, of in (
            ("state_names", d, "state"), ("state_units", d, "state"),
            ("measurement_names", p, "measurement"), ("measurement_units", p, "measurement"),
        ):  # fmt: skip
            to_labels(key, list(getattr(info, key)), count, of)

    @property
    def update_times(self) -> np.ndarray:
        """t_k = k * steps_per_update * sample_period for k = 1..K, s, shape (K,)."""
        return np.arange(1, self.model.updates + 1) * self.filter.update_period

    @property
    def truth_map(self) -> np.ndarray | None:
        """The (d, n) map of a truth with its own states (the filter's are map @ x_truth), or None."""
        return self.truth.map if isinstance(self.truth, MappedTruthModel) else None

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
                truth_from_settings(settings["truth"]),
            )
        except (KeyError, TypeError) as exc:
            expected = "complete custom model settings (model, filter, truth)"
            raise SettingError("settings", expected, f"{type(exc).__name__} {exc}") from None


def _check_same_shapes(f: LinearGaussianModel, t: LinearGaussianModel) -> None:
    """A truth over the filter's states: its phi and h have the filter's shapes."""
    for key in ("phi", "h"):
        if getattr(t, key).shape != getattr(f, key).shape:
            expected = f"shape {getattr(f, key).shape} like the filter's {key}"
            raise SettingError(f"truth.{key}", expected, str(getattr(t, key).shape))


# --- reading model files -------------------------------------------------------------------------

#: what each required key holds, for the error of a missing one
_EXPECTED = {"steps_per_update": "a positive integer", "updates": "a positive integer", "x0": "an array of numbers"}


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
        sample_period: the file's top-level keys), ``truth.KEY`` (the matrices of ``[truth]``, and its
        ``map`` and ``state_names``) and ``model.KEY`` (name, updates, the names and units). E.g.
        ``filter.w=[[0.01]]``, ``model.updates=60``. ``filter.KEY`` retunes the filter alone: where
        ``[truth]`` does not set KEY, the truth keeps the file's value (so that a sweep of a filter
        setting holds the world fixed); a truth with a ``map`` takes nothing from the filter.
    config : path, optional
        Must be None: a model file holds all its settings (``--config`` is for built-in scenarios).

    Raises
    ------
    SettingError
        One line: ``FILE: KEY: expected ..., got ...``, or ``KEY: ...`` naming the --set key at fault.
    """
    path = Path(path)
    if config is not None:
        expected = f"no config file with a model file ({path}; put the settings in the file or use --set)"
        raise SettingError("--config", expected, show(str(config)))
    document = read_toml(path, "model file")
    from kalcal.io.outputs import mark_inputs

    return mark_inputs(build_model(document, str(path), assignments), path)  # a job given it never removes the file


def model_fields(scenario: CustomModelScenario) -> dict[str, Any]:
    """A built model-file scenario as the fields of the model file it was read from (the keyword arguments
    of :class:`kalcal.Model`): the filter's matrices, the truth's where they differ, the labels, and the
    file as its source. Built again (``kalcal.Model(**fields).scenario(settings)``) it is the same scenario
    with ``settings`` applied as ``--set`` applies them to the file."""
    f, t, info = scenario.filter, scenario.truth, scenario.model
    keys = ("phi", "gamma", "h", "w", "v", "x0", "m0")
    truth = {key: getattr(t, key).tolist() for key in scenario.differing()}
    return dict(
        **{key: getattr(f, key).tolist() for key in keys},
        steps_per_update=int(f.steps_per_update), updates=int(info.updates), sample_period=float(f.sample_period),
        truth=truth or None, name=info.name, state_names=list(info.state_names), state_units=list(info.state_units),
        measurement_names=list(info.measurement_names), measurement_units=list(info.measurement_units),
        source=info.file,
    )


def parse_model(text: str, source: str, assignments: Iterable[str] = ()) -> CustomModelScenario:
    """A model file's text -> the validated scenario; ``source`` names the file in errors and outputs."""
    return build_model(parse_toml(text, source), source, assignments)


def build_model(document: dict[str, Any], source: str, assignments: Iterable[str] = ()) -> CustomModelScenario:
    """A model file's TOML tables and ``--set`` overrides -> the validated scenario.

    An error about a value the file holds names ``source``; one about an overridden value names the
    ``--set`` key alone.
    """
    origins = _apply_overrides(document, parse_assignments(assignments), source)
    try:
        return _build(document, source)
    except SettingError as exc:
        if exc.key in origins:
            raise exc.from_assignment(origins[exc.key]) from None
        raise exc.located(source=source) from None


def _apply_overrides(document: dict[str, Any], overrides: Mapping[str, str], source: str) -> dict[str, str]:
    """Write the overrides into the document; return each overridden document key's ``--set`` key."""
    origins: dict[str, str] = {}
    file_values: dict[str, Any] = {}  # the file's values of the filter's retuned matrices
    for key, text in overrides.items():
        section, _, name = key.partition(".")
        if name not in _SET_KEYS.get(section, ()) and key not in _TRUTH_MAP_SET_KEYS:
            known = "; ".join(f"{s}.{{{', '.join(keys)}}}" for s, keys in _SET_KEYS.items())
            raise unknown(key, f"a model file's setting ({known})", "setting")
        value = toml_value(key, text, bare_string=key == "model.name")  # a bare name needs no quotes
        if section == "truth":
            _truth_table(document, source)[name] = value
            origins[key] = key
            continue
        if section == "filter" and name in MODEL_KEYS and name in document:
            file_values.setdefault(name, document[name])
        document[name] = value
        origins[name] = key
    if file_values:
        # filter.KEY retunes the filter only: where [truth] does not set KEY the truth keeps the file's value
        # (as for built-in scenarios); a truth with a map has matrices of its own and takes none
        table = _truth_table(document, source)
        if "map" not in table:
            for name, value in file_values.items():
                table.setdefault(name, value)
    return origins


def _truth_table(document: dict[str, Any], source: str) -> dict[str, Any]:
    """The document's ``[truth]`` table, created empty where the file has none."""
    table = document.setdefault("truth", {})
    if not isinstance(table, dict):
        raise SettingError("truth", "a [truth] table of matrices", type_name(table), source)
    return table


def _array(key: str, value: Any) -> np.ndarray:
    return to_vector(key, value) if key.endswith("x0") else to_matrix(key, value)


def _truth_over_filter(
    truth: Mapping[str, Any], arrays: Mapping[str, np.ndarray], steps: int, period: float
) -> LinearGaussianModel:
    """A ``[truth]`` table without a map: its matrices over the filter's (``arrays``)."""
    truth_arrays = {key: _array(f"truth.{key}", truth[key]) if key in truth else arrays[key] for key in MODEL_KEYS}
    try:
        return LinearGaussianModel(**truth_arrays, steps_per_update=steps, sample_period=period)
    except SettingError as exc:
        got = exc.got
        if exc.key in MODEL_KEYS and exc.key not in truth:
            got += f" ([truth] does not set {exc.key}, so it is the filter's)"
        raise exc.located(key=f"truth.{exc.key}", got=got) from None


def _build(document: dict[str, Any], source: str) -> CustomModelScenario:
    for key in document:
        if key not in _TOP_KEYS and key != "truth":
            raise unknown(key, f"a model file's key ({', '.join(_TOP_KEYS)} or a [truth] table)")
    truth = document.get("truth", {})
    if not isinstance(truth, dict):
        raise SettingError("truth", "a [truth] table of matrices", type_name(truth))
    for key in truth:
        if key in MODEL_KEYS or (key in MAP_KEYS and "map" in truth):
            continue
        if "map" in truth:
            raise unknown(f"truth.{key}", f"a key of a [truth] with a map ({', '.join((*MAP_KEYS, *MODEL_KEYS))})")
        if key != "state_names":
            raise unknown(f"truth.{key}", f"a matrix of [truth] ({', '.join(MODEL_KEYS)})")
    if "state_names" in truth and "map" not in truth:
        expected = "a map beside it (state_names names the states of a truth with its own dimension)"
        raise SettingError("truth.state_names", expected, "no truth.map")
    for key in _REQUIRED:
        if key not in document:
            raise missing(key, _EXPECTED.get(key, "a matrix"))

    steps = to_positive_integer("steps_per_update", document["steps_per_update"])
    updates = to_positive_integer("updates", document["updates"])
    period = to_positive_number("sample_period", document.get("sample_period", 1.0), "a positive number of seconds")
    name = to_string("name", document.get("name", Path(source).stem))

    arrays = {key: _array(key, document[key]) for key in MODEL_KEYS}
    filter_model = LinearGaussianModel(**arrays, steps_per_update=steps, sample_period=period)
    if "map" in truth:
        truth_model = mapped_truth(truth, steps, period)
    else:
        truth_model = _truth_over_filter(truth, arrays, steps, period)

    d, p = filter_model.state_dim, filter_model.measurement_dim
    labels = {
        "state_names": tuple(f"x{i + 1}" for i in range(d)),
        "state_units": ("",) * d,
        "measurement_names": tuple(f"z{i + 1}" for i in range(p)),
        "measurement_units": ("",) * p,
    }
    for key in _NAME_KEYS:
        if key in document:
            labels[key] = to_labels(key, document[key])
    info = CustomModelInfo(name=name, file=source, updates=updates, **labels)
    return CustomModelScenario(info, filter_model, truth_model)
