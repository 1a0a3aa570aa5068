"""What the verification and the analysis ask of a model file: its problem, its model error's cause, its sources."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from kalcal.core.sources import Source, model_sources
from kalcal.core.steps import UpdateForm
from kalcal.errors import ConfigError
from kalcal.montecarlo.problem import FixedGainProblem, ProblemInfo
from kalcal.scenarios.model_file.model import CustomModelScenario, inputs_note
from kalcal.simulation.exact import truth_from_model


def custom_problem(
    scenario: CustomModelScenario, form: UpdateForm = "joseph", residual_pairs: bool = True
) -> FixedGainProblem:
    """A model file's filter against its truth, sampled exactly at the update rate (no per-sample engine)."""
    m = scenario.model
    info = ProblemInfo(
        scenario=m.name,
        update_times=scenario.update_times,
        state_names=m.state_names,
        state_units=m.state_units,
        measurement_names=m.measurement_names,
        measurement_units=m.measurement_units,
        capabilities=scenario.capabilities,
        notes=inputs_note(scenario, over_log=False),
    )
    try:
        if scenario.filter.diffuse:
            return _diffuse_problem(scenario, info, form, residual_pairs)
        return FixedGainProblem(
            info=info,
            filter_model=scenario.filter,
            truth=truth_from_model(scenario.truth, m.updates),
            form=form,
            residual_pairs=residual_pairs,
        )
    except np.linalg.LinAlgError:
        # NEES needs P_k^{-1}: a state that neither the prior, the process noise nor the fixes make uncertain
        raise ConfigError(
            f"{m.file}: the filter's covariance P_k is singular at some update (give the unobserved states "
            "prior variance in m0 or process noise through gamma and w)"
        ) from None


def _diffuse_problem(scenario: CustomModelScenario, info: ProblemInfo, form: UpdateForm, residual_pairs: bool):
    """A filter that starts diffuse: the exact diffuse gains, every update run, the checks from the end of the
    diffuse period on (:mod:`kalcal.scenarios.model_file.diffuse`); refused where the period never ends."""
    from kalcal.scenarios.model_file.diffuse import DiffuseFixedGainProblem, diffuse_flags, windowed

    flags = diffuse_flags(scenario)
    f, updates = scenario.filter, scenario.model.updates
    full = DiffuseFixedGainProblem(
        info=info, filter_model=dataclasses.replace(f, x0=np.where(flags, 0.0, f.x0)),
        truth=truth_from_model(scenario.truth, updates), form=form, residual_pairs=residual_pairs, diffuse=flags,
    )  # fmt: skip
    return windowed(scenario, full, "", f)


def custom_model_error_cause(scenario: CustomModelScenario) -> str:
    """The matrices of a model file's truth that can move the filter's mean error (x0, phi, h, and b where
    the known inputs move the truth otherwise than the filter predicts: over a log, a deterministic offset),
    or, for a truth with states of its own, that model (when a prior mean is nonzero or the inputs move it
    otherwise: else both means stay zero)."""
    from kalcal.scenarios.model_file.model import _input_mismatch

    driven = " (the known inputs u move the truth otherwise than the filter predicts)" if _input_mismatch(scenario) else ""
    if scenario.truth_map is not None:
        if not (np.any(scenario.truth.x0) or np.any(scenario.filter.x0) or driven):
            return ""
        n, d = scenario.truth.state_dim, scenario.filter.state_dim
        matrices = "x0, phi, h and b" if driven else "x0, phi and h"
        return f"the truth's own {n}-state model (its {matrices}, mapped to the filter's {d} state{'s' if d != 1 else ''}){driven}"
    keys = [k for k in scenario.differing() if k in ("x0", "phi", "h", *(("b",) if driven else ()))]
    return f"the truth's {' and '.join(keys)} differing from the filter's{driven}" if keys else ""


def model_error_sources(scenario: CustomModelScenario) -> list[Source]:
    """The error budget's sources of a model file's truth: its prior, process and measurement blocks, named by
    the truth's own states (x1, x2, ... for a larger truth without names)."""
    truth = scenario.truth
    names = getattr(truth, "state_names", None) or scenario.model.state_names  # a larger truth's own names
    if truth.state_dim != len(names):
        names = tuple(f"x{i + 1}" for i in range(truth.state_dim))
    return model_sources(truth, names, scenario.model.measurement_names)


def noise_settings(scenario: CustomModelScenario) -> dict[str, Callable[[float], CustomModelScenario]]:
    """The truth's noise matrices w, v and m0, each as factor -> the scenario with that std times ``factor``
    (the variance times its square), the filter's held."""
    out = {}
    for key in ("w", "v", "m0"):
        value = np.asarray(getattr(scenario.truth, key), dtype=float)
        if not np.any(value):
            continue

        def scaled(factor: float, key: str = key, value: np.ndarray = value) -> CustomModelScenario:
            return dataclasses.replace(scenario, truth=dataclasses.replace(scenario.truth, **{key: value * factor**2}))

        out[f"truth.{key}"] = scaled
    return out
