"""``kalcal fit MODEL.toml --data LOG``: a model file's noise covariances (and entries of phi) fitted to one log.

**Free parameters** (``--free``, a comma list; default: every positive diagonal entry of ``w`` and ``v``):

* ``filter.w`` / ``filter.v``: the single entry of a 1 x 1 covariance; ``filter.w.I`` / ``filter.v.I``:
  the I-th diagonal entry (1-based) of a larger one. The value is the file's own: a **variance** (the
  unit of the state or measurement squared). It is searched on a log scale over [start / 1e6,
  start x 1e6] (1e3 either side in std). Freeing a diagonal entry holds its correlations with the other
  entries: the covariance becomes S C S, S = diag(sqrt(new_ii / start_ii)) (1 on the entries held).
* ``filter.phi`` (1 x 1) / ``filter.phi.I.J``: an entry of phi (1-based row and column), searched on a
  linear scale within :data:`PHI_BOUNDS` = [-1, 1]: the range of an AR(1) coefficient that is stationary
  or (at +-1) a random walk; an explosive phi (|phi| > 1) is not searched. The file's value is the start
  and must lie in the range.

Refused in one line (a :class:`~kalcal.errors.ConfigError`, exit status 2): a key of none of these forms
(``filter.x0``, ``truth.w``, ...), an index out of range, an off-diagonal entry of w or v (``filter.w.1.2``:
it is held at its correlation), a variance whose start is 0 (the log-scale search needs a positive start:
give the file, or ``--set filter.w=...``, a positive value where the search should start), the variance of
a component whose std comes from a ``[data]`` std column (the column sets that row's V_j: the entry is not
a parameter of the fit), a key given twice. ``filter.m0.I`` is refused too: a prior variance is the spread
of one draw, x_0, which one log sees once; it informs the first few innovations only and is not identified
(give the state ``diffuse = [...]`` where nothing is known about it).

**The likelihood** is :func:`kalcal.core.timevarying_filter.loglik` over the file bound to the log
(:func:`~kalcal.scenarios.model_file.data.bind`), with the free values written into the bound model:
only W, the rows' V_j and Phi change. V_j = D_j V D_j (D_j from the std columns), so V -> S V S gives
V_j -> S V_j S (diagonal matrices commute): the bound rows are rescaled, not read again. With diffuse
states it is the conditional (diffuse) log-likelihood: the components conditioned on (those that see a
diffuse direction) are not in it; statsmodels' exact diffuse ``llf`` is it plus ``diffuse_term``
(fit.json's ``diffuse_term`` at the estimate), a constant in W and V.

The search, the intervals, "consistent with 0" and the flatness verdicts are
:func:`kalcal.fitting.mle.maximize`'s. The outputs: fit.json, fit.png and ``model.toml``, the model file
with the fitted values written in (its filter's matrices; a ``[truth]`` key the file set apart from its
filter stays the file's), which ``calibrate`` takes as it is, and ``verify`` where it takes the file
(its header says which: a diffuse filter is verified where its [truth] gives the world's m0, a file whose
rows come from a log is verified with ``--data LOG``).
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from kalcal.calibration.diagnostics import innovation_diagnostics
from kalcal.core.timevarying import TimeVaryingModel
from kalcal.core.timevarying_filter import filter_model, loglik
from kalcal.errors import ConfigError, DataError
from kalcal.fitting.mle import Free, maximize
from kalcal.fitting.result import FitResult, fitted_point, interval_text
from kalcal.scenarios.model_file.calibrate import normalized_series

if TYPE_CHECKING:
    from kalcal.scenarios.model_file.data import BoundModel
    from kalcal.scenarios.model_file.model import CustomModelScenario

#: a variance is searched over this factor either side of its start (1e3 in std)
RANGE = 1e6
#: an entry of phi is searched within these bounds (linear scale)
PHI_BOUNDS = (-1.0, 1.0)
#: the file name of the fitted model file among a fit's outputs
MODEL_NAME = "model.toml"
OUTPUT_NAMES = ("fit.json", MODEL_NAME, "fit.png")

_KEY = re.compile(r"^filter\.(w|v|phi|m0)((?:\.[^.]*)*)$")


@dataclass(frozen=True)
class FreeEntry:
    """One free parameter: its key, the matrix ("w", "v" or "phi") and the entry's 0-based row and column."""

    key: str
    matrix: str
    row: int
    col: int

    @property
    def scale(self) -> str:
        return "linear" if self.matrix == "phi" else "log"


def _index(key: str, text: str, size: int, what: str) -> int:
    if not text.isdigit() or not 1 <= int(text) <= size:
        raise ConfigError(f"--free: {key}: expected a 1-based {what} in 1..{size}, got {text!r}")
    return int(text) - 1


def fit_refusal(scenario: CustomModelScenario) -> str:
    """Why the file cannot be fitted ("" when it can), in words that follow ``FILE:``."""
    if scenario.data is None:
        return "kalcal fit needs a [data] table in the file (which log columns feed the model) to read --data LOG"
    return ""


def likelihood_refusal(scenario: CustomModelScenario, bound: BoundModel, run=None) -> str:
    """Why the log gives the fit nothing to maximize ("" when it does), in words that follow the log's name.

    Refused: a log of one row (no step: w is not in the likelihood, and one innovation tests nothing) and a
    log whose likelihood holds no measurement (every measurement empty, or every one conditioned on by the
    diffuse start). Which components are conditioned on depends on the rows of h and the diffuse states,
    not on w or v, so the file's own values decide it before the search (``run``: the filter over the
    bound log at those values, when it has run already)."""
    rows = int(bound.z.shape[0])
    if rows < 2:
        return "the log has one row: no step (w is not in the likelihood) and one innovation: nothing to fit"
    run = filter_model(bound.filter, bound.z) if run is None else run
    measured, conditioned = int(np.count_nonzero(run.measured)), int(np.count_nonzero(run.conditioned))
    if measured == 0:
        return f"no measurement in its {rows} rows (every measurement cell empty or NaN): nothing in the likelihood"
    if measured == conditioned:
        return (
            f"all {measured} measurement(s) are conditioned on by the diffuse start of "
            f"{', '.join(scenario.filter.diffuse)}: nothing left in the likelihood (a log that measures beyond "
            "the diffuse period is needed)"
        )
    return ""


def free_entries(scenario: CustomModelScenario, keys: Sequence[str]) -> list[FreeEntry]:
    """``--free``'s keys -> the entries they free, each checked (module docstring); ConfigError otherwise."""
    f = scenario.filter
    stds = scenario.data.stds if scenario.data is not None else ()
    entries, seen = [], {}
    for key in keys:
        match = _KEY.match(key)
        if match is None:
            raise ConfigError(
                f"--free: {key}: expected filter.w, filter.v, filter.phi (1 x 1), filter.w.I, filter.v.I (a diagonal "
                "entry, 1-based) or filter.phi.I.J of a model file"
            )
        matrix, parts = match.group(1), [part for part in match.group(2).split(".")[1:]]
        if matrix == "m0":
            raise ConfigError(
                f"--free: {key}: a prior variance is not fitted: it is the spread of one draw, x_0, which one log sees "
                "once (it informs the first innovations only); give the state diffuse = [...] where nothing is known of it"
            )
        array = getattr(f, matrix)
        size = array.shape[0]
        if matrix == "phi":
            if not parts and size == 1:
                row = col = 0
            elif len(parts) == 2:
                row, col = _index(key, parts[0], size, "row of phi"), _index(key, parts[1], size, "column of phi")
            else:
                one = " (or filter.phi, phi being 1 x 1)" if size == 1 else ""
                raise ConfigError(f"--free: {key}: expected filter.phi.I.J, a 1-based entry of the {size} x {size} phi{one}")
            start = float(array[row, col])
            if not PHI_BOUNDS[0] <= start <= PHI_BOUNDS[1]:
                raise ConfigError(
                    f"--free: {key}: the file's value {start:g}, the search's start, lies outside the bounds "
                    f"[{PHI_BOUNDS[0]:g}, {PHI_BOUNDS[1]:g}] of an entry of phi"
                )
        else:
            if len(parts) == 2:
                raise ConfigError(
                    f"--free: {key}: an off-diagonal entry of {matrix} is not free (it is held at its correlation "
                    f"as the diagonal entries move); free a diagonal entry, filter.{matrix}.I"
                )
            if not parts and size == 1:
                row = 0
            elif len(parts) == 1 and size > 1:
                row = _index(key, parts[0], size, f"diagonal entry of the {size} x {size} {matrix}")
            elif size == 1:
                raise ConfigError(f"--free: {key}: {matrix} is 1 x 1: its key is filter.{matrix}")
            else:
                raise ConfigError(f"--free: {key}: {matrix} is {size} x {size}: expected filter.{matrix}.I, I in 1..{size}")
            col = row
            start = float(array[row, row])
            if not start > 0:
                raise ConfigError(
                    f"--free: {key}: its start, the file's variance, is {start:g}: the log-scale search needs a positive "
                    f"start (set one in the file or with --set filter.{matrix}=...)"
                )
            if matrix == "v" and row < len(stds) and stds[row]:
                raise ConfigError(
                    f"--free: {key}: measurement {row + 1}'s std comes from the data column {stds[row]!r}, which sets "
                    "V_j on every row: the file's variance is not a parameter of the fit"
                )
        entry = FreeEntry(key, matrix, row, col)
        if (matrix, row, col) in seen:
            raise ConfigError(f"--free: {key} and {seen[(matrix, row, col)]} name the same entry")
        seen[(matrix, row, col)] = key
        entries.append(entry)
    if not entries:
        raise ConfigError("--free: expected at least one key")
    return entries


def default_free(scenario: CustomModelScenario) -> list[str]:
    """Every diagonal entry of w and v with a positive start, v's without a std column (the default of --free)."""
    f = scenario.filter
    stds = scenario.data.stds if scenario.data is not None else ()
    keys = []
    for matrix in ("w", "v"):
        array = getattr(f, matrix)
        for i in range(array.shape[0]):
            if array[i, i] > 0 and not (matrix == "v" and i < len(stds) and stds[i]):
                keys.append(f"filter.{matrix}" if array.shape[0] == 1 else f"filter.{matrix}.{i + 1}")
    return keys


def _frozen(array: np.ndarray) -> np.ndarray:
    array = np.ascontiguousarray(array, dtype=float)
    array.setflags(write=False)
    return array


class BoundLikelihood:
    """log L of the bound model with the free entries written in (thread-safe: nothing is mutated).

    Parameters
    ----------
    scenario : CustomModelScenario
        The file (its filter's values are the starts).
    bound : BoundModel
        The file over the log (:func:`~kalcal.scenarios.model_file.data.bind`).
    entries : list of FreeEntry
    """

    def __init__(self, scenario: CustomModelScenario, bound: BoundModel, entries: Sequence[FreeEntry]):
        self.bound, self.entries, self.base = bound, list(entries), bound.filter
        self.w0, self.phi0 = np.array(self.base.w), np.array(self.base.phi)
        #: each entry's start: the file's value (a variance of w or v, an entry of phi)
        self.start = {e.key: float(getattr(scenario.filter, e.matrix)[e.row, e.col]) for e in self.entries}

    def matrices(self, values: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(Phi, W, V_j rows) with ``values`` written in."""
        phi, w_scale = self.phi0.copy(), np.ones(self.w0.shape[0])
        v_scale = np.ones(self.base.measurement_dim)
        for e in self.entries:
            if e.key not in values:
                continue
            value = float(values[e.key])
            if e.matrix == "phi":
                phi[e.row, e.col] = value
            elif e.matrix == "w":
                w_scale[e.row] = np.sqrt(value / self.w0[e.row, e.row])
            else:
                v_scale[e.row] = np.sqrt(value / self.start[e.key])
        w = w_scale[:, None] * self.w0 * w_scale[None, :]
        v = v_scale[None, :, None] * self.base.v * v_scale[None, None, :]
        return phi, w, v

    def model_at(self, values: Mapping[str, float]) -> TimeVaryingModel:
        """The bound filter's model with ``values`` written in, built without TimeVaryingModel's checks (W and
        the V_j are positive rescalings of checked ones, Phi is finite)."""
        phi, w, v = self.matrices(values)
        model = object.__new__(TimeVaryingModel)
        fields = dict(self.base.__dict__)
        fields.update(phi=_frozen(phi), w=_frozen(w), v=_frozen(v))
        for name, value in fields.items():
            object.__setattr__(model, name, value)
        return model

    def __call__(self, values: Mapping[str, float]) -> float:
        return loglik(self.model_at(values), self.bound.z)


def _unit(scenario: CustomModelScenario, e: FreeEntry) -> str:
    """A variance's unit: the state's (w: through gamma, the state its column drives when that is one state)
    or the measurement's, squared; phi: that of state I over state J."""
    info = scenario.model
    if e.matrix == "v":
        unit = info.measurement_units[e.row]
        return f"({unit})^2" if unit else ""
    if e.matrix == "phi":
        top, bottom = info.state_units[e.row], info.state_units[e.col]
        return "" if top == bottom else f"{top or '1'}/{bottom or '1'}"
    driven = np.flatnonzero(scenario.filter.gamma[:, e.row])
    unit = info.state_units[int(driven[0])] if driven.size == 1 else ""
    return f"({unit})^2" if unit else ""


def fitted_matrices(scenario: CustomModelScenario, like: BoundLikelihood, chosen: Mapping[str, float]) -> dict[str, list]:
    """The file's phi, w and v with ``chosen`` written in (off-diagonals held at their correlation)."""
    f = scenario.filter
    phi = np.array(f.phi)
    w_scale, v_scale = np.ones(f.w.shape[0]), np.ones(f.v.shape[0])
    for e in like.entries:
        if e.key not in chosen:
            continue
        value = float(chosen[e.key])
        if e.matrix == "phi":
            phi[e.row, e.col] = value
        elif e.matrix == "w":
            w_scale[e.row] = np.sqrt(value / f.w[e.row, e.row])
        else:
            v_scale[e.row] = np.sqrt(value / f.v[e.row, e.row])
    w = w_scale[:, None] * f.w * w_scale[None, :]
    v = v_scale[:, None] * f.v * v_scale[None, :]
    for e in like.entries:  # the fitted diagonal exactly as reported, not through sqrt and back
        if e.key in chosen and e.matrix != "phi":
            (w if e.matrix == "w" else v)[e.row, e.row] = float(chosen[e.key])
    return {"phi": phi.tolist(), "w": w.tolist(), "v": v.tolist()}


def model_text(scenario: CustomModelScenario, matrices: Mapping[str, list], header: Sequence[str]) -> str:
    """model.toml: ``header`` as comments, then the model file with ``matrices`` as its filter's (a
    ``[truth]`` key that differed from the filter stays as it was; the others follow the filter, as in
    the file)."""
    from kalcal.api.model import Model
    from kalcal.scenarios.model_file.model import model_fields

    fields = model_fields(scenario)
    fields.update(matrices)
    fields.pop("source", None)
    text = Model(**fields).document()
    return "".join(f"# {line}\n" for line in header) + text


def _takers(scenario: CustomModelScenario) -> list[str]:
    """model.toml's line on the commands that take it: the fitted file differs from the file only in phi, w
    and v, none of which decides whether verify takes it (the rows of h, the std columns, the diffuse
    states, the truth's inputs and the updates do), so the file's own answer is the fitted file's."""
    why = scenario.without_log()
    if not why:
        return ["`kalcal calibrate`, `kalcal fit` and `kalcal verify` take this file as it is."]
    return ["`kalcal calibrate` and `kalcal fit` take this file as it is; `kalcal verify` without a log does not:",
            f"{why}."]


def fit_model_file(
    scenario: CustomModelScenario,
    log: Any,
    *,
    free: Sequence[str] | None = None,
    profile: bool = False,
    confidence: float = 0.95,
    topic: str | None = None,
    options=None,
) -> FitResult:
    """Maximum-likelihood entries of a model file's w, v and phi on one log, with intervals and the fitted
    filter's innovation diagnostics (module docstring).

    Parameters
    ----------
    scenario : CustomModelScenario
        A model file with a ``[data]`` table; its filter's values are the starts, the entries not free stay.
    log : path or DataFrame
        The log, as :func:`~kalcal.scenarios.model_file.data.bind` reads it.
    free : sequence of str, optional
        Keys (module docstring); default :func:`default_free`.
    profile, confidence
        As :func:`kalcal.fitting.mle.maximize`.
    topic : str, optional
        A bag's or ULog's topic.
    options : FitOptions, optional
        Its ``bootstrap`` (B), ``seed``, ``threads`` and ``client``: the parametric bootstrap
        (:mod:`kalcal.fitting.bootstrap`) over logs drawn by :func:`draw_log`.

    Returns
    -------
    FitResult
        As ``kalcal fit`` saves it (:func:`~kalcal.fitting.run.for_command`): ``settings`` holds
        ``{"filter": {phi, w, v}}`` and, where the file's truth follows its filter, the same matrices under
        ``"truth"`` (so that ``settings=`` gives the model of model.toml); ``filter_text`` is model.toml's
        text and ``filter_name`` its name.
    """
    from kalcal.fitting.run import for_command
    from kalcal.scenarios.model_file.data import bind

    keys = list(default_free(scenario) if free is None else free)
    if not keys:
        raise ConfigError(f"{scenario.model.file}: no positive diagonal entry of w or v to fit: name the keys with --free")
    entries = free_entries(scenario, keys)
    bound = bind(scenario, log, topic=topic)
    refusal = likelihood_refusal(scenario, bound)
    if refusal:
        raise DataError(f"{bound.source}: kalcal fit {scenario.model.file}: {refusal}")
    like = BoundLikelihood(scenario, bound, entries)
    parameters = []
    for e in entries:
        start = like.start[e.key]
        if e.scale == "log":
            parameters.append(Free(e.key, start, start / RANGE, start * RANGE, _unit(scenario, e)))
        else:
            # [-1, 1] bounds phi itself (stationary to a random walk): refits there are at a bound, as a variance's at 0
            parameters.append(Free(e.key, start, PHI_BOUNDS[0], PHI_BOUNDS[1], _unit(scenario, e), scale="linear",
                                   bounded=True))
    fit = maximize(like, parameters, profile=profile, confidence=confidence)
    chosen = fitted_point(fit)
    from kalcal.fitting.bootstrap import bootstrap_fit

    fitted = like.model_at(chosen)

    def draw(rng):
        z = draw_log(fitted, bound.z, rng)
        return lambda values: loglik(like.model_at({**chosen, **values}), z)

    boot = bootstrap_fit(options, draw, parameters, fit, confidence)
    run = filter_model(like.model_at(chosen), bound.z)
    # the series calibrate tests (one function for both): rows that measure different components are
    # pooled, component by component, rather than dropped (a log whose rows never measure every
    # component would otherwise leave nothing to test and a NaN verdict)
    series, labels, used = normalized_series(run, tuple(bound.measurement_names))
    diagnostics = innovation_diagnostics(series, labels)
    adequate = diagnostics.consistent
    adequacy = diagnostics.verdict if adequate else (
        f"{diagnostics.verdict}. Even the best settings leave the innovations inconsistent: the model lacks "
        "something, e.g. a state, time-correlated noise, or noise that is not Gaussian"
    )
    counted = int(np.count_nonzero(run.measured & ~run.conditioned))
    notes = [
        "the variances are searched on a log scale over 1e6 either side of the file's value (1e3 in std); "
        f"an entry of phi on a linear scale within [{PHI_BOUNDS[0]:g}, {PHI_BOUNDS[1]:g}]; off-diagonal entries "
        "of w and v are held at their correlation"
    ]
    if scenario.filter.diffuse:
        notes.append(
            f"{', '.join(scenario.filter.diffuse)} start diffuse: log L is the conditional likelihood, without the "
            f"{int(run.conditioned.sum())} measurement(s) conditioned on; an exact diffuse llf (statsmodels') is it "
            f"plus diffuse_term ({run.diffuse_term:.6g} at the estimate), a constant in w and v"
        )
    if scenario.filter.diffuse and any(e.matrix == "phi" for e in entries):
        notes.append(
            "phi is free and states start diffuse: diffuse_term may depend on phi (never on w or v), so the maximizer "
            "of phi under the conditional likelihood may differ from an exact diffuse likelihood's (it does not where "
            "the conditioned measurements see the diffuse states before any step, as in an AR(1) plus noise)"
        )
    if np.unique(run.measured[used], axis=0).shape[0] > 1:
        notes.append(
            f"the innovation diagnostics test the {series.shape[0]} normalized components of the {used.size} measured "
            "rows after the diffuse period as one series (rows measure different components)"
        )
    matrices = fitted_matrices(scenario, like, chosen)
    settings = {"filter": dict(matrices)}
    follows = [key for key in ("phi", "w", "v") if key not in scenario.differing()] if scenario.truth_map is None else []
    if follows:
        settings["truth"] = {key: matrices[key] for key in follows}
    header = [
        f"kalcal fit: {', '.join(keys)} fitted by maximum likelihood to {bound.source}",
        f"({counted} measurements in the likelihood, log L = {fit.loglik:.6g}, {fit.interval_method} intervals).",
        *(f"{p.name}: {p.note if not p.identified else 'fitted, ' + interval_text(p)}".rstrip() for p in fit.parameters.values()),
        *_takers(scenario),
    ]
    if not adequate:
        header.append(f"NOT ADEQUATE: {adequacy}")
    result = FitResult.from_search(
        scenario.model.name, fit, fixes=counted, nobs_name="measurements", adequate=adequate, adequacy=adequacy,
        diagnostics={**diagnostics.as_dict(), "series": list(labels), "rows_used": int(used.size)}, notes=notes, settings=settings, confidence=confidence,
        extra={"diffuse_term": float(run.diffuse_term), "model_file": scenario.model.file}, bootstrap=boot,
    )  # fmt: skip
    linear = tuple(key for key, p in result.parameters.items() if p.scale == "linear")
    result = for_command(result, f"fit {scenario.model.file}", {"data": bound.source}, keys,
                         model_text(scenario, matrices, header), linear=linear)
    return dataclasses.replace(result, filter_name=MODEL_NAME)


def draw_log(fitted: TimeVaryingModel, z: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Measurements drawn from the fitted filter model over the bound log's rows (its inputs, h rows and std
    columns are the model's), NaN where the log has none (its missing pattern), shape (J, p)
    (:func:`kalcal.scenarios.model_file.simulate.draw`).

    A state that starts diffuse starts at its x0 exactly: the conditional likelihood the fit maximizes does
    not depend on a diffuse state's first value (it conditions on the measurements that determine it)."""
    from kalcal.scenarios.model_file.simulate import draw

    if fitted.diffuse.any():
        proper = object.__new__(TimeVaryingModel)
        fields = dict(fitted.__dict__)
        keep = ~np.asarray(fitted.diffuse, dtype=bool)
        fields.update(m0=_frozen(fitted.m0 * keep[:, None] * keep[None, :]), diffuse=_frozen(np.zeros_like(keep)))
        for name, value in fields.items():
            object.__setattr__(proper, name, value)
        fitted = proper
    _, simulated = draw(fitted, rng)
    simulated[~np.isfinite(z)] = np.nan
    return simulated


def fit_logs(scenario: CustomModelScenario, logs: Mapping[str, Any], options) -> FitResult:
    """:meth:`CustomModelScenario.fit`: the log and options checked, then :func:`fit_model_file`, then what
    its files need (:func:`~kalcal.fitting.run.for_command`)."""
    from kalcal.errors import KalcalError
    from kalcal.io.logs import is_frame
    from kalcal.io.outputs import mark_inputs

    if options.gate is not None:
        raise KalcalError("--gate: not available for a model file (its filter has no innovation gate)")
    if logs.get("imu") is not None or logs.get("gps") is not None:
        raise KalcalError("--imu/--gps: not used by a model file (it reads --data, laid out by its [data] table)")
    log = logs.get("data")
    if log is None:
        raise KalcalError(f"--data: required for {scenario.model.file} (a log laid out as its [data] table says)")
    result = fit_model_file(scenario, log, free=options.free, profile=options.profile, confidence=options.confidence,
                            topic=logs.get("topic"), options=options)
    return result if is_frame(log) else mark_inputs(result, log)
