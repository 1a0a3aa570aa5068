"""The scale-bias fit: its diffuse likelihood against closed forms, interval coverage over simulated logs."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from kalcal.core.likelihood import innovation_loglik
from kalcal.core.steps import nis
from kalcal.filters.regression import run_regression_filter
from kalcal.scenarios.scale_bias.filter import regressors
from kalcal.scenarios.scale_bias.fit import DRIFT, NOISE, fit_scale_bias
from kalcal.scenarios.scale_bias.likelihood import diffuse_loglik
from kalcal.scenarios import build_scenario
from kalcal.scenarios.scale_bias.simulation import sample_scale_bias


def scenario(**settings):
    return build_scenario("scale-bias", None, [f"{key}={value}" for key, value in settings.items()])


def one_log(seed, **settings):
    sc = scenario(**settings)
    s = sample_scale_bias(sc, np.random.default_rng(seed), 1)
    return sc, s.time, s.reference[0], s.sensor[0], s.theta[0]


def test_without_drift_the_diffuse_likelihood_is_the_closed_form_of_a_flat_prior_given_the_first_two_samples():
    _, _, v, z, _ = one_log(0)
    r = 0.3**2
    h = regressors(z)
    loglik, used, _ = diffuse_loglik(v, z, 0.3, 0.0)
    theta = np.linalg.lstsq(h, v, rcond=None)[0]
    rss = float(np.sum((v - h @ theta) ** 2))
    k = v.size
    # log p(v_3..K | v_1, v_2) = log int N(v; H theta, R I) d theta - log int N(v_1:2; H_2 theta, R I) d theta
    expected = (
        -0.5 * k * np.log(2 * np.pi * r) - rss / (2 * r) + np.log(2 * np.pi)
        - 0.5 * np.linalg.slogdet(h.T @ h / r)[1] + np.log(abs(np.linalg.det(h[:2])))
    )
    assert used == k - 2
    assert loglik == pytest.approx(expected, rel=1e-10)


def test_with_drift_it_is_the_limit_of_the_filter_with_an_ever_wider_prior():
    _, _, v, z, _ = one_log(1, **{"scenario.drift": "random-walk", "truth.parameter_drift_std": 0.01})
    loglik, used, normalized = diffuse_loglik(v, z, 0.25, 0.01)
    kappa = 1e6
    run = run_regression_filter(v, regressors(z), np.zeros(2), kappa * np.eye(2), 0.25**2, 0.01**2 * np.eye(2))
    s, e = run.innovation_var[2:, None, None], run.residual[2:, None]
    reference = innovation_loglik(e, s)
    # the finite prior differs from the diffuse one by O(P_data / kappa) in each term
    assert loglik == pytest.approx(reference, rel=1e-6)
    # each sample's normalized innovation: its square the NIS of the numpy steps (kalcal.core.steps.nis)
    assert np.allclose(normalized[2:], e[:, 0] / np.sqrt(s[:, 0, 0]), rtol=1e-5, atol=1e-8) and np.all(np.isnan(normalized[:2]))
    np.testing.assert_allclose(normalized[2:] ** 2, nis(e, s), rtol=2e-5, atol=1e-12)


def test_the_fit_does_not_depend_on_the_prior_of_a_and_b():
    sc, t, v, z, _ = one_log(2)
    base = fit_scale_bias(sc, t, v, z, free=[NOISE])
    shifted = fit_scale_bias(scenario(**{"filter.bias": 5.0, "filter.bias_std": 0.01, "filter.scale_error": 0.3}), t, v, z, free=[NOISE])
    assert shifted.parameters[NOISE].value == pytest.approx(base.parameters[NOISE].value, rel=1e-6)


def test_a_missing_sample_is_a_prediction_only():
    _, _, v, z, _ = one_log(3)
    v = v.copy()
    v[10] = np.nan
    full = diffuse_loglik(v, z, 0.2, 0.0)
    kept = np.isfinite(v)
    assert full[1] == np.count_nonzero(kept) - 2
    assert full[0] == pytest.approx(diffuse_loglik(v[kept], z[kept], 0.2, 0.0)[0], rel=1e-12)


def test_95_percent_intervals_cover_the_true_noise_and_drift_at_about_their_rate():
    logs, covered = 40, {NOISE: 0, DRIFT: 0}
    settings = {
        "scenario.duration": 60, "scenario.drift": "random-walk", "truth.parameter_drift_std": 0.002,
        "truth.reference_noise_std": 0.3, "truth.sensor_noise_std": 0.0,
    }
    truth = {NOISE: 0.3, DRIFT: 0.002}
    for seed in range(logs):
        sc, t, v, z, _ = one_log(100 + seed, **settings)
        result = fit_scale_bias(sc, t, v, z)
        assert result.converged
        for key, p in result.parameters.items():
            covered[key] += int(p.identified and p.ci_low <= truth[key] <= p.ci_high)
    # two-sided binomial acceptance region of 40 draws at p = 0.95, at 1e-3
    low, high = stats.binom.ppf(5e-4, logs, 0.95), stats.binom.isf(5e-4, logs, 0.95)
    for key, count in covered.items():
        assert low <= count <= high, (key, count, low, high)
