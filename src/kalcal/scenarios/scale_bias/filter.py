"""The calibration note's filter for the scale/bias scenario: its prior, noise and regressors.

The generic recursion is :func:`kalcal.filters.regression.run_regression_filter`; this module supplies
what the scenario's ``filter`` settings say: x_0^+ = theta(a, b), P_0^+ from the prior of a and b,
R = sigma_w^2 (``filter.noise_model``), Q = parameter_drift_std^2 I and the regressor h_k = [z_k, 1].
"""

from __future__ import annotations

import numpy as np

from kalcal.filters.regression import RegressionRun, run_regression_filter
from kalcal.scenarios.scale_bias.settings import ScaleBiasScenario


def regressors(sensor: np.ndarray) -> np.ndarray:
    """h_k = [z_k, 1] for sensor readings z of shape (..., K): shape (..., K, 2)."""
    sensor = np.asarray(sensor, dtype=float)
    return np.stack([sensor, np.ones_like(sensor)], axis=-1)


def filter_scale_bias(
    scenario: ScaleBiasScenario, reference: np.ndarray, sensor: np.ndarray, form: str | None = None
) -> RegressionRun:
    """The note's filter over reference and sensor logs of shape (..., K) (a batch or one series).

    x_0^+ and P_0^+ are the filter's prior, R its sigma_w^2, Q its parameter_drift_std^2 I; the regressor
    of sample k is [z_k, 1]. ``form`` defaults to ``filter.form``.
    """
    prior = scenario.filter_prior()
    return run_regression_filter(
        reference,
        regressors(sensor),
        prior.mean,
        prior.cov,
        scenario.filter_noise_variance(),
        scenario.filter_process_noise(),
        form or scenario.filter_settings.form,
    )
