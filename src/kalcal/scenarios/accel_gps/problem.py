"""What the verification and the analysis ask of accel-gps: its problem, its model error's cause, its sources.

The report's filter against its truth (:func:`accel_gps_problem`, with the exact and the per-sample
engines), the settings a verification refuses (:func:`refuse_log_faults`), the sentence naming the model
error (:func:`accel_gps_model_error_cause`), the error budget's sources (:func:`accel_gps_sources`) and
the truth's noise settings the sensitivity scales (:func:`noise_settings`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from functools import partial

import numpy as np

from kalcal.core.model import LinearGaussianModel
from kalcal.core.sources import Source, covariance_sources
from kalcal.core.steps import UpdateForm, interval_transition
from kalcal.models.settings import SettingError, show
from kalcal.montecarlo.problem import FixedGainProblem, ProblemInfo
from kalcal.scenarios.accel_gps.sampled import sample_accel_gps_errors
from kalcal.scenarios.accel_gps.settings import AccelGpsScenario
from kalcal.scenarios.accel_gps.truth import accel_gps_process_noise, accel_gps_transitions, accel_gps_truth


def sampled_normals_per_realization(scenario: AccelGpsScenario) -> int:
    """Normals the per-sample engine draws: p0, v0, b, sample 0 (and s); per interval m samples and a
    noise per fix component (2, or 1 with velocity-only fixes; each 1 + nu with Student-t fixes), and m bias-noise draws when the bias
    drifts. See :mod:`kalcal.scenarios.accel_gps.sampled`."""
    s = scenario.scenario
    m = s.steps_per_update
    drifts = scenario.truth.bias_step_variance(s.sample_period) > 0
    fix_draws = len(scenario.fix_states) * (1 + scenario.truth.gps_measurement_dof)  # Student t: nu more each
    return 4 + int(scenario.has_scale) + s.n_updates * (m + fix_draws + (m if drifts else 0))


def accel_gps_filter_transitions(scenario: AccelGpsScenario, filter_model: LinearGaussianModel) -> np.ndarray:
    """The filter's transition of each interval with a scale-factor state, (K, 4, 4).

    The filter's own Phi^m (its bias decay, from the filter's settings) with the scale column of the
    acceleration profile, the one thing the filter shares with the truth: it depends on no truth setting
    but ``accel_amplitude`` and ``accel_frequency``.
    """
    s = scenario.scenario
    phi_m, _ = interval_transition(filter_model.phi, filter_model.gamma, filter_model.w, s.steps_per_update)
    return accel_gps_transitions(scenario, np.broadcast_to(phi_m, (s.n_updates, *phi_m.shape)))


def accel_gps_problem(
    scenario: AccelGpsScenario, form: UpdateForm = "joseph", residual_pairs: bool = True
) -> FixedGainProblem:
    """The report's filter against its truth, with the exact and the per-sample (sampled) engines.

    The truth's log-only GNSS faults (``truth.gps_latency``, ``gps_outlier_*``) are not in it: a
    verification and an analysis refuse them first (:func:`refuse_log_faults`).
    """
    s = scenario.scenario
    info = ProblemInfo(
        scenario=scenario.NAME,
        update_times=s.update_times(),
        state_names=scenario.state_names,
        state_units=scenario.state_units,
        measurement_names=scenario.measurement_names,
        measurement_units=scenario.measurement_units,
        capabilities=scenario.capabilities,
    )
    truth = accel_gps_truth(scenario)
    filter_model = scenario.filter_model()
    return FixedGainProblem(
        info=info,
        filter_model=filter_model,
        truth=truth,
        filter_transitions=accel_gps_filter_transitions(scenario, filter_model) if scenario.has_scale else None,
        sampled=partial(sample_accel_gps_errors, scenario),
        sampled_normals=sampled_normals_per_realization(scenario),
        sampled_block=partial(_sampled_block, scenario),
        form=form,
        residual_pairs=residual_pairs,
    )


def refuse_log_faults(scenario: AccelGpsScenario) -> None:
    """Raise a one-line SettingError naming the first log-only GNSS fault set in ``scenario.truth``.

    ``kalcal simulate`` writes them into logs; the exact truth has no time stamps to shift and no
    gross fix errors (Student-t fix noise, ``truth.gps_noise``, is a truth of its own), so a verification or
    analysis of them would verify something else.
    """
    t = scenario.truth
    for key in ("gps_latency", "gps_outlier_rate"):
        value = getattr(t, key)
        if value != 0 and (key == "gps_latency" or t.gps_outlier_std > 0):
            raise SettingError(
                f"truth.{key}",
                "0 in a verification (a log-only setting of kalcal simulate: the Monte Carlo's truth has no "
                "time stamps or gross fix errors)",
                show(value),
            )


def accel_gps_model_error_cause(scenario: AccelGpsScenario) -> str:
    """A sentence naming what makes the truth depart from the filter's model, for check details."""
    s = scenario.scenario
    causes = []
    if s.truth == "analytic":
        lag = " (the rectangle rule lags a(t) by half a sample)" if s.integration == "euler" else ""
        causes.append(f"the {s.integration} integration of the accelerometer against the analytic truth{lag}")
    f, t = scenario.filter_settings, scenario.truth
    if (f.position0_mean, f.velocity0_mean) != (t.position0_mean, t.velocity0_mean):
        causes.append("the filter's prior mean differing from the truth's")
    return " and ".join(causes)


def accel_gps_sources(scenario: AccelGpsScenario) -> list[Source]:
    """prior:position, prior:velocity, prior:bias (, prior:scale), process:accel (, process:bias),
    measurement:position (absent with velocity-only fixes), measurement:velocity."""
    model = scenario.truth_model()
    return covariance_sources(model.m0, model.v, accel_gps_process_noise(scenario), scenario.state_names, scenario.measurement_names)


def noise_settings(scenario: AccelGpsScenario) -> dict[str, Callable[[float], AccelGpsScenario]]:
    """The truth's noise settings (each ``*_std``), each as factor -> the scenario with that std times
    ``factor``, the filter's own settings held where they were."""
    truth, pinned = scenario.truth, scenario.filter_settings
    out = {}
    for field in dataclasses.fields(truth):
        name = field.name
        value = getattr(truth, name)
        if not name.endswith("_std") or not isinstance(value, float) or value <= 0:
            continue

        def scaled(factor: float, name: str = name, value: float = value) -> AccelGpsScenario:
            return dataclasses.replace(
                scenario,
                truth=dataclasses.replace(truth, **{name: value * factor}),
                filter=dataclasses.replace(scenario.filter, **{name: getattr(pinned, name)}),
            )

        out[f"truth.{name}"] = scaled
    return out


def _sampled_block(scenario, *args):
    """The sampled engine's compiled block (:func:`kalcal.scenarios.accel_gps.sampled_kernels.accel_gps_block_sums`),
    its numba module loaded when a run first calls it, not when a problem is built."""
    from kalcal.scenarios.accel_gps.sampled_kernels import accel_gps_block_sums

    return accel_gps_block_sums(scenario, *args)
