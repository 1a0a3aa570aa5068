"""The accel-gps truth at the update rate: its transitions, the Euler or trapezoid scheme's model error, its noise.

The accel-gps form of :mod:`kalcal.simulation.exact`'s truth: the per-sample model composed over each GPS
interval (with the trapezoid rule's shared boundary sample), the scale column of the acceleration
profile, and the deterministic model error of an integration scheme against the analytic truth.
"""

from __future__ import annotations

import numpy as np

from kalcal.core.steps import interval_transition
from kalcal.scenarios.accel_gps.mechanization import integrate, interval_weights
from kalcal.linalg import psd_factor
from kalcal.scenarios.accel_gps.settings import AccelGpsScenario
from kalcal.simulation.exact import UpdateRateTruth, truth_from_model


def accel_gps_model_error(scenario: AccelGpsScenario) -> np.ndarray:
    """D_k: the error state left by integrating the noise-free, bias-free a(t_j) against the truth.

    Zero for ``truth = "discrete"``; for the analytic truth it is the integration scheme's own error
    (the rectangle rule's half-sample lag for Euler). Shape (K, d), m and m/s (bias and scale columns zero).
    """
    s = scenario.scenario
    error = np.zeros((s.n_updates, 4 if scenario.has_scale else 3))
    if s.truth == "discrete":
        return error
    fix_index = np.arange(1, s.n_updates + 1) * s.steps_per_update
    true_accel = scenario.true_accel(s.sample_times())
    position, velocity = integrate(true_accel, s.sample_period, 0.0, 0.0, s.integration)
    exact_position, exact_velocity = scenario.analytic_motion(s.update_times())
    error[:, 0] = exact_position - position[fix_index]
    error[:, 1] = exact_velocity - velocity[fix_index]
    return error


def accel_gps_transitions(scenario: AccelGpsScenario, transitions: np.ndarray) -> np.ndarray:
    """The transition of each interval with the scale factor's column: minus the position and velocity
    the true acceleration alone produces over the interval (from rest, with the scenario's scheme).

    ``transitions`` (K, 4, 4) are those of the model without it; returns a new (K, 4, 4) array.
    """
    s = scenario.scenario
    m = s.steps_per_update
    accel = scenario.true_accel(s.sample_times())
    weights = interval_weights(s.integration, s.sample_period, m)  # (m + 1, 2)
    windows = np.lib.stride_tricks.sliding_window_view(accel, m + 1)[::m][: s.n_updates]  # (K, m + 1)
    result = np.array(transitions, dtype=float)
    result[:, :2, 3] = -(windows @ weights)
    return result


def accel_noise_weights(scenario: AccelGpsScenario) -> tuple[np.ndarray, bool]:
    """The weight of each accelerometer noise sample of an interval in the error state, (m + 1, d), and
    whether the first and last are shared with the neighbouring intervals (the trapezoid rule).

    The error state gains -C_i sigma_a w_{s+i} from each sample i = 0..m of the interval.
    """
    s = scenario.scenario
    m = s.steps_per_update
    weights = np.zeros((m + 1, scenario.truth_model().state_dim))
    weights[:, :2] = -scenario.truth.accel_noise_std * interval_weights(s.integration, s.sample_period, m)
    return weights, bool(np.any(weights[m] != 0.0))


def accel_gps_process_noise(scenario: AccelGpsScenario) -> list[tuple[str, np.ndarray, float]]:
    """The interval's process noise by independent source: ``accel`` (the accelerometer's white noise
    inside the interval; its shared boundary sample has variance 1 in the last entry when the scheme shares
    one, 0 otherwise) and, when the bias drifts, ``bias``; each ``(name, Q share (d, d), boundary variance)``.
    """
    model = scenario.truth_model()
    m = scenario.scenario.steps_per_update
    weights, shared = accel_noise_weights(scenario)
    interior = weights[1:m] if shared else weights[:m]
    out = [("accel", interior.T @ interior, 1.0 if shared else 0.0)]
    if model.gamma.shape[1] > 1:
        # The bias's own noise (random walk or Gauss-Markov), independent of the accelerometer's.
        out.append(("bias", interval_transition(model.phi, model.gamma[:, 1:], model.w[1:, 1:], m)[1], 0.0))
    return out


def accel_gps_truth(scenario: AccelGpsScenario) -> UpdateRateTruth:
    """The accelerometer/GPS error state at the fixes, exactly in distribution for either scheme.

    The fixes' noise is Gaussian or, with ``truth.gps_noise = "student-t"``, unit-variance Student t times
    the same G (``UpdateRateTruth.measurement_dof``). The truth model's per-sample Phi and bias-noise input are the scheme's own
    (:func:`~kalcal.scenarios.accel_gps.discretization.error_transition`), so a drifting bias composes exactly over an
    interval; the accelerometer noise, which the trapezoid rule shares between steps, by its weights.
    """
    s = scenario.scenario
    model = scenario.truth_model()
    m = s.steps_per_update
    weights, shared = accel_noise_weights(scenario)
    noise = sum(q for _, q, _ in accel_gps_process_noise(scenario))
    base = truth_from_model(model, s.n_updates, accel_gps_model_error(scenario))
    transitions = accel_gps_transitions(scenario, base.transitions) if scenario.has_scale else base.transitions
    return UpdateRateTruth(
        transitions=transitions,
        noise_factor=psd_factor(noise),
        boundary_in=weights[0] if shared else np.zeros(model.state_dim),
        boundary_out=weights[m],
        model_error=base.model_error,
        x0_mean=base.x0_mean,
        x0_factor=base.x0_factor,
        h=base.h,
        measurement_factor=base.measurement_factor,
        # Student-t fixes keep the covariance G G^T: the analysis (second moments) is still exact for them
        measurement_dof=scenario.truth.gps_measurement_dof,
    )
