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
noise input may have another q), or, with a ``map``, has n states of its own (:mod:`kalcal.scenarios.model_file.truth`).

Every problem is a :class:`~kalcal.models.settings.SettingError` of one line,
``FILE: KEY: expected ..., got ...`` (``KEY: expected ..., got ...`` for a value given by ``--set KEY=...``):
unknown and missing keys, wrong types, a matrix whose shape does not fit (through LinearGaussianModel's
own validation), a covariance that is not symmetric positive semi-definite.

In a run's ``summary.json`` the scenario's settings are the sections ``model`` (name, file, updates,
names, units), ``filter`` and ``truth`` (each model's matrices, steps_per_update, sample_period, and b,
h_columns, diffuse where the file has them), ``data`` (the ``[data]`` table, where the file has one) and,
for a run over a log, ``log`` (the log's resolved path and SHA-256,
:class:`~kalcal.scenarios.model_file.over_log.LoggedModelScenario`): enough to rebuild the scenario without
the file (:meth:`CustomModelScenario.from_settings`), and the keys that ``--set`` accepts
(:func:`load_model_file`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from kalcal.core.model import LinearGaussianModel
from kalcal.scenarios import scenario_names
from kalcal.scenarios.model_file.data import DATA_KEYS, DataTable, data_table
from kalcal.scenarios.model_file.linear import FileModel, split_h
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

#: required in every file; steps_per_update and updates too in a file without [data]
_REQUIRED = MODEL_KEYS


_TIMING = ("steps_per_update", "updates")
_NAME_KEYS = ("state_names", "state_units", "measurement_names", "measurement_units")
#: what a model file adds to the time-invariant model: known inputs and the states started diffuse
_FILE_KEYS = ("b", "diffuse")
_TOP_KEYS = ("name", "sample_period", *_TIMING, *MODEL_KEYS, *_FILE_KEYS, *_NAME_KEYS)
#: ``--set`` keys by section, as the run's summary.json lists the settings.
_SET_KEYS = {
    "model": ("name", "updates", *_NAME_KEYS),
    "filter": (*MODEL_KEYS, *_FILE_KEYS, "steps_per_update", "sample_period"),
    "truth": (*MODEL_KEYS, "b"),
    "data": DATA_KEYS,
}
#: the keys of a [truth] table over the filter's states
_TRUTH_KEYS = (*MODEL_KEYS, "b")
#: ``--set`` keys of a truth with its own states, beside those its section lists (truth.map, truth.state_names)
_TRUTH_MAP_SET_KEYS = tuple(f"truth.{key}" for key in MAP_KEYS)
_RESERVED_NAMES = scenario_names()


def is_model_file(scenario: str) -> bool:
    """Whether a SCENARIO argument names a model file (it ends in ``.toml``) rather than a built-in."""
    return str(scenario).lower().endswith(".toml")


def is_custom_settings(settings: Mapping[str, Any]) -> bool:
    """Whether a summary's ``settings`` are those of a custom model (sections model, filter, truth, and
    data for a file with a [data] table)."""
    return set(settings) in ({"model", "filter", "truth"}, {"model", "filter", "truth", "data"})


@dataclass(frozen=True)
class CustomModelInfo:
    """What labels a custom model's results (section ``model``).

    name : the scenario's name in outputs; file : the model file as given (for the record);
    updates : K, measurement updates to verify (None: a file with [data] that does not set it, whose
    model is only run over a log); state_names, state_units : length d;
    measurement_names, measurement_units : length p. Units are SI labels ("" for none).
    """

    name: str
    file: str
    updates: int | None
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
    filter : FileModel
        What the filter believes (the file's top-level matrices, its known-input matrix b, the entries
        of h that name data columns, its diffuse states).
    truth : FileModel or MappedTruthModel
        What the world does: the ``[truth]`` table over the filter's matrices (same d, p,
        steps_per_update and sample_period as the filter), or, with a ``map``, a model of its own n
        states (:mod:`kalcal.scenarios.model_file.truth`; same p and timing, map of shape (d, n)).
    data : DataTable or None
        The file's ``[data]`` table: how a log's columns feed the model (:mod:`kalcal.scenarios.model_file.data`).
    """

    NAME: ClassVar[str] = "custom"
    #: the options of :class:`~kalcal.results.calibration.CalibrateOptions` its calibrate takes
    CALIBRATE_OPTIONS: ClassVar[tuple[str, ...]] = ("smooth", "windows")
    SUMMARY: ClassVar[str] = "a linear Gaussian model read from a TOML file (docs/custom-models.md)"

    @property
    def label(self) -> str:
        """What its refusals call it: the file it was read from."""
        return f"a model file ({self.model.file})"

    @property
    def capabilities(self) -> Capabilities:
        """A linear Gaussian filter with gains fixed before any data, sampled at the update rate only (no
        per-sample engine: the file has no samples between updates) for the updates the file sets. A
        property, not a class constant: what it has depends on the file it was read from (a file whose
        model needs a log, or that sets no updates, has no verify or analyze: :meth:`without_log`)."""
        why = self.without_log()
        # a sweep is a verify per value of one number of the file (kalcal.api.sweep.model_file_cells)
        commands = {"report"} if why else {"verify", "analyze", "sweep", "report"}
        refusals = (("verify", why), ("analyze", why), ("sweep", why)) if why else ()
        from kalcal.scenarios.model_file.fit import fit_refusal

        why_fit = fit_refusal(self)  # fit needs a [data] table (the log's layout)
        commands |= set() if why_fit else {"fit"}
        refusals += (("fit", why_fit),) if why_fit else ()
        if self.data is not None:  # a log's columns reach the model through its [data] table
            commands |= {"calibrate", "simulate"}
        else:
            no_data = (
                "it has no [data] table, which says which columns of a log are its time, measurements and inputs "
                "(docs/custom-models.md)"
            )
            refusals = (*refusals, ("calibrate", no_data), ("simulate", no_data))
        return Capabilities(
            exact_analysis=True,
            fixed_gains=True,
            engines=("exact",),
            long_run=False,
            commands=frozenset(commands),
            why_not=(("--engine", "use the exact engine"), ("--long-run", "set updates in the file instead"), *refusals),
        )

    def without_log(self) -> str:
        """Why the file's model cannot be verified or analyzed without a log ("" when it can), in words
        that follow ``FILE:``: the rows of h, the stds or the truth's inputs come from a log, or the file
        sets no updates, or the filter starts diffuse and the [truth] gives no m0 of its own. A filter that
        starts diffuse is verified from the end of its diffuse period on
        (:mod:`kalcal.scenarios.model_file.diffuse`)."""
        f, t, data = self.filter, self.truth, self.data
        columns = tuple(dict.fromkeys((*f.data_columns, *t.data_columns)))
        if columns:
            return (
                f"its h names data columns ({', '.join(columns)}): its rows come from a log, so it is not verified "
                "without one (--data LOG)"
            )
        if data is not None and any(data.stds):
            stds = ", ".join(c for c in data.stds if c)
            return f"its measurement stds come from data columns ({stds}): it is not verified without a log (--data LOG)"
        if f.diffuse:
            from kalcal.scenarios.model_file.diffuse import truth_prior_refusal

            why = truth_prior_refusal(self)
            if why:
                return why
        mismatch = _input_mismatch(self)
        if mismatch == "b":
            return (
                "its truth's inputs (b) differ from the filter's, so the filter's error depends on the inputs u: "
                "it is not verified without a log (--data LOG); with the truth's b equal to the filter's it does not"
            )
        if mismatch:
            return (
                f"its truth's {mismatch} differs from the filter's beside known inputs, so the inputs u move the truth "
                "otherwise than the filter's prediction and the filter's error depends on u: it is not verified "
                "without a log (--data LOG)"
            )
        if self.model.updates is None:
            return "it sets no updates (the model file's updates and steps_per_update say how long to verify it without a log)"
        return ""

    def sweep_refusal(self, key: str) -> str:
        """Why ``kalcal sweep`` does not sweep ``key`` of this file ("" when it does: one number of the model,
        :func:`kalcal.scenarios.model_file.entries.sweep_refusal`), in words that follow ``sweep: KEY:``."""
        from kalcal.scenarios.model_file.entries import sweep_refusal

        return sweep_refusal(self, key, over_log=getattr(self, "log", None) is not None)

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

    def error_sources(self) -> list:
        """The truth's prior, process and measurement blocks."""
        from kalcal.scenarios.model_file.problem import model_error_sources

        return model_error_sources(self)

    def noise_settings(self) -> dict:
        """The truth's w, v and m0, each as factor -> the scenario with it scaled."""
        from kalcal.scenarios.model_file.problem import noise_settings

        return noise_settings(self)

    def run_length(self) -> tuple[int, float]:
        """The file's updates: t_k = k update_period."""
        count = int(self.model.updates or 0)
        return count, count * float(self.filter.update_period)

    def truth_is_filter(self) -> bool:
        """False: its exact analysis says whether the truth equals the filter."""
        return False

    def over_log(self, data, command: str, topic: str | None = None):
        """The file over the log ``data`` (``--data LOG``, a bag's or ULog's ``topic``): its rows, stds and
        update rows from the log, the gains the same in every realization
        (:func:`kalcal.scenarios.model_file.over_log.over_log`)."""
        from kalcal.scenarios.model_file.over_log import over_log

        return over_log(self, data, topic)

    def simulate(self, seed: int, logs=None):
        """A log in the file's [data] layout over the rows of ``logs["data"]``, its measurements drawn with
        ``seed`` (:func:`kalcal.scenarios.model_file.simulate.simulate_logs`)."""
        from kalcal.scenarios.model_file.simulate import simulate_logs
        from kalcal.scenarios.protocol import require

        require(self, "simulate")  # a file without a [data] table, or one bound to a log, has none
        return simulate_logs(self, seed, logs)

    def output_names(self, command: str) -> tuple[str, ...]:
        """The files ``command`` writes (simulate: data.csv, truth.json; calibrate: estimates.csv, summary.json;
        fit: fit.json, fit.png, model.toml)."""
        from kalcal.scenarios.protocol import require

        require(self, command)
        if command == "fit":
            from kalcal.scenarios.model_file.fit import OUTPUT_NAMES

            return OUTPUT_NAMES
        if command == "simulate":
            from kalcal.scenarios.model_file.simulate import OUTPUT_NAMES

            return OUTPUT_NAMES
        if command == "calibrate":
            from kalcal.scenarios.model_file.calibrate import OUTPUT_NAMES

            return OUTPUT_NAMES
        return ()

    def calibrate(self, logs, options):
        """The filter (and smoother) over ``logs["data"]`` (:func:`kalcal.scenarios.model_file.calibrate.calibrate_logs`)."""
        from kalcal.scenarios.model_file.calibrate import calibrate_logs
        from kalcal.scenarios.protocol import require

        require(self, "calibrate")  # a file without a [data] table, or one bound to a log, has none
        return calibrate_logs(self, logs, options)

    def fit(self, logs, options):
        """The file's w, v (and phi) entries fitted to ``logs`` (``data``) with ``options``
        (:class:`~kalcal.fitting.run.FitOptions`): :func:`kalcal.scenarios.model_file.fit.fit_logs`."""
        from kalcal.scenarios.model_file.fit import fit_logs
        from kalcal.scenarios.protocol import require

        require(self, "fit")
        return fit_logs(self, logs, options)

    model: CustomModelInfo
    filter: FileModel
    truth: FileModel
    data: DataTable | None = None

    def __post_init__(self) -> None:
        f, t, info = self.filter, self.truth, self.model
        if not isinstance(f, FileModel):  # a LinearGaussianModel given in Python: no inputs, no data
            object.__setattr__(self, "filter", f := _file_model(f))
        if not isinstance(t, FileModel):
            object.__setattr__(self, "truth", t := _file_model(t))
        d, p = f.state_dim, f.measurement_dim
        if isinstance(t, MappedTruthModel):
            t.check_fits(d, p)
        else:
            _check_same_shapes(f, t)
        timing = (f.steps_per_update, f.sample_period)
        if (t.steps_per_update, t.sample_period) != timing:
            expected = f"the filter's steps_per_update and sample_period {timing}"
            raise SettingError("truth.steps_per_update", expected, str((t.steps_per_update, t.sample_period)))
        if info.updates is not None or self.data is None:
            to_positive_integer("updates", info.updates)
        if t.input_dim != f.input_dim:
            expected = f"{f.input_dim} column{'s' if f.input_dim != 1 else ''} like the filter's b"
            raise SettingError("truth.b", expected, f"shape {t.b.shape}")
        if t.diffuse:
            raise SettingError("truth.diffuse", "no diffuse states (the world's prior is proper)", show(list(t.diffuse)))
        columns = tuple(dict.fromkeys((*f.data_columns, *t.data_columns)))
        if columns and self.data is None:
            expected = "a [data] table beside an h that names data columns (the log's columns feed the model)"
            raise SettingError("data", expected, f"none (h names {', '.join(columns)})")
        if f.input_dim and self.data is None:
            raise SettingError("data.inputs", f"{f.input_dim} column names beside b (the known inputs)", "no [data] table")
        if self.data is not None:
            if len(self.data.measurements) != p:
                raise SettingError("data.measurements", f"{p} column names, one per row of h", show(list(self.data.measurements)))
            if len(self.data.inputs) != f.input_dim:
                raise SettingError("data.inputs", f"{f.input_dim} column names, one per column of b", show(list(self.data.inputs)))
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
        _check_diffuse(f, info.state_names)

    @property
    def update_times(self) -> np.ndarray:
        """t_k = k * steps_per_update * sample_period for k = 1..K, s, shape (K,) (empty without updates)."""
        return np.arange(1, (self.model.updates or 0) + 1) * self.filter.update_period

    def bind(self, log, *, topic: str | None = None):
        """The file over one log (a path :mod:`kalcal.io.logs` reads, or a DataFrame): its filter's (and
        truth's) :class:`~kalcal.core.timevarying.TimeVaryingModel`, z and the times
        (:func:`kalcal.scenarios.model_file.data.bind`)."""
        from kalcal.scenarios.model_file.data import bind

        return bind(self, log, topic=topic)

    def step_grid(self):
        """The file's (filter, truth) as TimeVaryingModels without a log: ``updates`` updates on the step grid
        (:func:`kalcal.scenarios.model_file.data.step_grid`)."""
        from kalcal.scenarios.model_file.data import step_grid

        return step_grid(self)

    @property
    def truth_map(self) -> np.ndarray | None:
        """The (d, n) map of a truth with its own states (the filter's are map @ x_truth), or None."""
        return self.truth.map if isinstance(self.truth, MappedTruthModel) else None

    def differing(self) -> tuple[str, ...]:
        """The matrices in which the truth departs from the filter, in MODEL_KEYS order (h where its numbers
        or the columns it names differ), then b."""
        f, t = self.filter, self.truth

        def differs(key: str) -> bool:
            a, b = getattr(f, key), getattr(t, key)
            return not np.array_equal(a, b, equal_nan=a.shape == b.shape) or (key == "h" and f.h_columns != t.h_columns)

        return tuple(k for k in (*MODEL_KEYS, "b") if differs(k))

    @classmethod
    def from_settings(cls, settings: Mapping[str, Mapping[str, Any]]) -> CustomModelScenario:
        """Rebuild the scenario from a summary's ``settings`` (sections model, filter, truth, and data
        where the file had a [data] table)."""
        try:
            info = dict(settings["model"])
            for key in _NAME_KEYS:
                info[key] = tuple(info[key])
            data = settings.get("data")
            return cls(
                CustomModelInfo(**info),
                FileModel(**settings["filter"]),
                truth_from_settings(settings["truth"]),
                None if data is None else DataTable(**data),
            )
        except (KeyError, TypeError) as exc:
            expected = "complete custom model settings (model, filter, truth)"
            raise SettingError("settings", expected, f"{type(exc).__name__} {exc}") from None


def _file_model(model: LinearGaussianModel) -> FileModel:
    """A LinearGaussianModel as a FileModel without inputs, data columns or diffuse states."""
    import dataclasses

    return FileModel(**{field.name: getattr(model, field.name) for field in dataclasses.fields(LinearGaussianModel)})


def _check_diffuse(f: FileModel, names: tuple[str, ...]) -> None:
    """Diffuse states are named states, each once, whose rows and columns of m0 are zero (nothing dropped
    silently: a prior variance the file gives a diffuse state is an error)."""
    for name in f.diffuse:
        if name not in names:
            raise SettingError("diffuse", f"state names (of {', '.join(names)})", show(name))
    if len(set(f.diffuse)) != len(f.diffuse):
        raise SettingError("diffuse", "each state once", show(list(f.diffuse)))
    flags = np.array([name in f.diffuse for name in names], dtype=bool)
    if np.any(f.m0[flags]) or np.any(f.m0[:, flags]):
        expected = f"zero rows and columns for the diffuse states ({', '.join(f.diffuse)}: no prior information)"
        raise SettingError("m0", expected, show(f.m0))


def _inputs_cancel(scenario: CustomModelScenario) -> bool:
    """Whether the known inputs move the truth's filter-state part as they move the filter, so that the
    error e = M x - xhat and the innovations do not depend on u (M the truth's map, the identity without one).

    By linearity each is its input-free value plus a deterministic offset: the truth's response to u
    (g_{j+1} = Phi_t g_j + B_t u_j) mapped, less the filter's response to its own prediction of it
    (f_{j+1} = Phi f_j + B u_j): M g_j - f_j in the error, H_t g_j - H f_j in the innovation. Both vanish for
    every u when M B_t = B, M Phi_t = Phi M and H_t = H M (then M g_j = f_j by induction), which is what is
    checked: without a map, a truth with the filter's b, phi and h (the same data columns in h); with a
    map, the three products to 1e-12 of the largest entry and no h naming data columns. A file whose
    filter has no inputs has nothing to cancel. A truth that departs from them (its own b, or its own phi
    or h while the filter has inputs) makes the error depend on u (:mod:`kalcal.scenarios.model_file.logged`
    carries the offset over a log)."""
    return not _input_mismatch(scenario)


def inputs_note(scenario: CustomModelScenario, over_log: bool) -> tuple[str, ...]:
    """What a verification says of the file's known inputs (``ProblemInfo.notes``): nothing without inputs;
    where they cancel (:func:`_inputs_cancel`), that the error and innovations do not depend on u (over a
    log the inputs enter the estimates alone; without one the estimates are those of u = 0); over a log
    where they do not cancel, that the error carries the inputs' deterministic offset."""
    if scenario.filter.input_dim == 0 and scenario.truth.input_dim == 0:
        return ()
    if _inputs_cancel(scenario):
        said = ("the known inputs u move the truth and the filter's prediction alike, so the filter's error and "
                "innovations do not depend on u")
        if over_log:
            return (said + ": the log's inputs enter the estimates alone (the filter's own response to them)",)
        return (said + "; without a log the inputs are unknown, so the estimates shown, and the orthogonality "
                "check where the mean error is not zero, are those of u = 0",)
    if over_log:
        return (f"the truth's {_input_mismatch(scenario)} moves it with the known inputs otherwise than the filter "
                "predicts: the error carries a deterministic offset from the log's inputs, the same in every "
                "realization, which the Monte Carlo and the exact analysis carry (the mean-error check sees it)",)
    return ()


def _input_mismatch(scenario: CustomModelScenario) -> str:
    """The first of b, phi and h in which the truth moves with the inputs otherwise than the filter ("" for
    none: :func:`_inputs_cancel`)."""
    f, t, m = scenario.filter, scenario.truth, scenario.truth_map
    if f.input_dim == 0 and t.input_dim == 0:
        return ""
    if m is None:
        return next((k for k in ("b", "phi", "h") if k in scenario.differing()), "")

    def close(a: np.ndarray, b: np.ndarray) -> bool:
        return a.shape == b.shape and np.allclose(a, b, rtol=0.0, atol=1e-12 * max(1.0, float(np.max(np.abs(b), initial=0.0))))

    if not close(m @ t.b, f.b):
        return "b"
    if not close(m @ t.phi, f.phi @ m):
        return "phi"
    return "h" if f.h_columns or t.h_columns or not close(t.h, f.h @ m) else ""


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
        setting holds the world fixed); a truth with a ``map`` takes nothing from the filter. One number
        of a matrix: ``filter.v=0.5`` (1 x 1), ``filter.w.2=0.1`` (a diagonal entry, its correlations
        held), ``filter.x0.2=3``, ``truth.phi.1.2=0.2`` (:mod:`kalcal.scenarios.model_file.entries`).
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

    def value(model: FileModel, key: str) -> Any:
        return _file_h(model) if key == "h" else getattr(model, key).tolist()

    mapped = isinstance(t, MappedTruthModel)
    # a truth with a map holds all its matrices (and its b where it has inputs), else those that differ
    keys = (*MODEL_KEYS, *(("b",) if t.input_dim else ())) if mapped else scenario.differing()
    truth = {key: value(t, key) for key in keys}
    if mapped:
        truth["map"] = t.map.tolist()
        if t.state_names is not None:
            truth["state_names"] = list(t.state_names)
    data = scenario.data
    return dict(
        **{key: value(f, key) for key in MODEL_KEYS},
        steps_per_update=int(f.steps_per_update), updates=None if info.updates is None else int(info.updates),
        sample_period=float(f.sample_period), truth=truth or None, name=info.name,
        state_names=list(info.state_names), state_units=list(info.state_units),
        measurement_names=list(info.measurement_names), measurement_units=list(info.measurement_units),
        b=f.b.tolist() if f.input_dim else None, diffuse=list(f.diffuse) or None,
        data=None if data is None else _data_fields(data), source=info.file,
    )  # fmt: skip


def _file_h(model: FileModel) -> list[list[Any]]:
    """h as the file writes it: numbers, and the name of each data column it takes."""
    rows = model.h.tolist()
    for i, row in enumerate(model.h_columns):
        for k, name in enumerate(row):
            if name:
                rows[i][k] = name
    return rows


def _data_fields(data: DataTable) -> dict[str, Any]:
    """A [data] table as the file writes it: the keys it sets (time and stds only where given)."""
    fields: dict[str, Any] = {"measurements": list(data.measurements)}
    if data.time:
        fields["time"] = data.time
    if data.inputs:
        fields["inputs"] = list(data.inputs)
    if data.stds:
        fields["stds"] = list(data.stds)
    fields["step_tolerance"] = data.step_tolerance
    return fields


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
    import copy

    from kalcal.scenarios.model_file.entries import MATRICES, current, is_entry_key, set_entry, set_number

    origins: dict[str, str] = {}
    file_values: dict[str, Any] = {}  # the file's values of the filter's retuned matrices
    original = copy.deepcopy(document)  # the truth's entries start from the file's values, not --set's
    for key, text in overrides.items():
        section, _, name = key.partition(".")
        if is_entry_key(key):  # one number of a matrix (filter.w.2): the whole matrix with it set
            section, name, value = set_entry(key, toml_value(key, text), document, original)
        elif name not in _SET_KEYS.get(section, ()) and key not in _TRUTH_MAP_SET_KEYS:
            known = "; ".join(f"{s}.{{{', '.join(keys)}}}" for s, keys in _SET_KEYS.items())
            raise unknown(key, f"a model file's setting ({known}, or one number of a matrix: KEY.I, KEY.I.J)", "setting")
        else:
            value = toml_value(key, text, bare_string=key == "model.name")  # a bare name needs no quotes
            if name in MATRICES and section in ("filter", "truth") and isinstance(value, (int, float)) and not isinstance(value, bool):
                # a number for a 1 x 1 matrix (filter.v=0.5): refused, naming the keys of its numbers, for a larger one
                value = set_number(key, section, name, value, current(document, original, section, name))
        if section in ("truth", "data"):
            table = _truth_table(document, source) if section == "truth" else _data_table(document, source)
            table[name] = value
            origins[f"{section}.{name}"] = key  # an error about truth.w names the --set key (truth.w.2)
            continue
        if section == "filter" and name in _TRUTH_KEYS and name in document:
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


def _data_table(document: dict[str, Any], source: str) -> dict[str, Any]:
    """The document's ``[data]`` table, created empty where the file has none."""
    table = document.setdefault("data", {})
    if not isinstance(table, dict):
        raise SettingError("data", "a [data] table", type_name(table), source)
    return table


def _array(key: str, value: Any) -> np.ndarray:
    return to_vector(key, value) if key.endswith("x0") else to_matrix(key, value)


def _truth_over_filter(truth: Mapping[str, Any], f: FileModel, arrays: Mapping[str, np.ndarray]) -> FileModel:
    """A ``[truth]`` table without a map: its matrices over the filter's (``arrays``, as the file gives
    them, and f's b and the columns its h names)."""
    h, columns = split_h("truth.h", truth["h"]) if "h" in truth else (arrays["h"], f.h_columns)
    truth_arrays = {
        key: _array(f"truth.{key}", h if key == "h" else truth[key]) if key in truth else arrays[key] for key in MODEL_KEYS
    }
    b = to_matrix("truth.b", truth["b"]) if "b" in truth else f.b
    try:
        return FileModel(
            **truth_arrays, steps_per_update=f.steps_per_update, sample_period=f.sample_period, b=b, h_columns=columns
        )
    except SettingError as exc:
        got = exc.got
        if exc.key in _TRUTH_KEYS and exc.key not in truth:
            got += f" ([truth] does not set {exc.key}, so it is the filter's)"
        raise exc.located(key=f"truth.{exc.key}", got=got) from None


def _build(document: dict[str, Any], source: str) -> CustomModelScenario:
    for key in document:
        if key not in _TOP_KEYS and key not in ("truth", "data"):
            raise unknown(key, f"a model file's key ({', '.join(_TOP_KEYS)}, a [truth] or a [data] table)")
    truth = document.get("truth", {})
    if not isinstance(truth, dict):
        raise SettingError("truth", "a [truth] table of matrices", type_name(truth))
    for key in truth:
        if key in _TRUTH_KEYS or (key in MAP_KEYS and "map" in truth):
            continue
        if "map" in truth:
            raise unknown(f"truth.{key}", f"a key of a [truth] with a map ({', '.join((*MAP_KEYS, *_TRUTH_KEYS))})")
        if key != "state_names":
            raise unknown(f"truth.{key}", f"a matrix of [truth] ({', '.join(_TRUTH_KEYS)})")
    if "state_names" in truth and "map" not in truth:
        expected = "a map beside it (state_names names the states of a truth with its own dimension)"
        raise SettingError("truth.state_names", expected, "no truth.map")
    has_data = "data" in document
    # steps_per_update and updates say how to run the model without a log: with [data] a log can say it
    for key in (*_TIMING, *_REQUIRED) if not has_data else _REQUIRED:
        if key not in document:
            raise missing(key, _EXPECTED.get(key, "a matrix"))
    if "updates" in document and "steps_per_update" not in document:
        expected = "a positive integer beside updates (the model steps between two of them)"
        raise SettingError("steps_per_update", expected, "nothing")

    steps = to_positive_integer("steps_per_update", document.get("steps_per_update", 1))
    updates = to_positive_integer("updates", document["updates"]) if "updates" in document else None
    period = to_positive_number("sample_period", document.get("sample_period", 1.0), "a positive number of seconds")
    name = to_string("name", document.get("name", Path(source).stem))

    h, columns = split_h("h", document["h"])
    arrays = {key: _array(key, h if key == "h" else document[key]) for key in MODEL_KEYS}
    b = to_matrix("b", document["b"]) if "b" in document else None
    diffuse = to_labels("diffuse", document["diffuse"]) if "diffuse" in document else ()
    filter_model = FileModel(
        **arrays, steps_per_update=steps, sample_period=period, b=b, h_columns=columns, diffuse=diffuse
    )
    if "map" in truth:
        truth_model = mapped_truth(truth, steps, period)
    else:
        truth_model = _truth_over_filter(truth, filter_model, arrays)

    d, p = filter_model.state_dim, filter_model.measurement_dim
    data = data_table(document["data"], d, p, filter_model.input_dim) if has_data else None
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
    return CustomModelScenario(info, filter_model, truth_model, data)
