"""The Monte Carlo agrees with the exact analysis within its sampling bounds, for truths the filter
does not model: mistuned noise, a drifting bias, a Gauss-Markov bias with the trapezoid rule.

Every comparison is z = (ensemble - exact) / sd with the exact sd of the ensemble statistic under the
Gaussian truth, held to a Bonferroni bound over its family at alpha = 1e-4 (fixed seeds).
"""

from __future__ import annotations

import numpy as np
import pytest

from kalcal.analysis.fixed_gain import analyze_problem
from kalcal.models.config import apply_settings
from kalcal.scenarios.accel_gps.settings import AccelGpsScenario
from kalcal.montecarlo.accumulators import ensemble_statistics
from kalcal.montecarlo.engine import run_monte_carlo
from kalcal.montecarlo.scenarios import build_problem
from tests._helpers import bonferroni_k

N = 20_000
TRUTHS = {
    "mistuned noise": {"truth.accel_noise_std": 0.05, "filter.accel_noise_std": 0.02, "truth.gps_position_std": 2.0, "filter.gps_position_std": 1.0},
    "drifting bias": {"truth.bias_walk_std": 5e-4, "filter.bias_walk_std": 0.0},
    "gauss-markov trapezoid": {"scenario.integration": "trapezoid", "truth.bias_correlation_time": 10.0, "filter.bias_correlation_time": 0.0},
}


def _assert_within(z, what):
    z = np.asarray(z)
    bound = bonferroni_k(z.size, 1e-4)
    assert np.max(np.abs(z)) < bound, f"{what}: max |z| = {np.max(np.abs(z)):.2f} >= {bound:.2f}"


@pytest.mark.parametrize("name", list(TRUTHS))
def test_ensemble_agrees_with_exact_analysis(name):
    scenario = apply_settings(AccelGpsScenario(), TRUTHS[name])
    problem, _ = build_problem(scenario)
    exact = analyze_problem(problem)
    stats = ensemble_statistics(run_monte_carlo(problem, N, seed=11, workers=1).sums)
    m, c = exact.moments.mean_error, exact.moments.error_cov
    var = np.diagonal(c, axis1=1, axis2=2)
    _assert_within((stats.mean_error - m) / np.sqrt(var / N), "mean error")
    iu = np.triu_indices(c.shape[-1])
    sd = np.sqrt((c**2 + var[:, :, None] * var[:, None, :]) / N)
    _assert_within(((stats.error_cov - c) / sd)[:, iu[0], iu[1]], "error covariance")
    # the analysis sees what the filter does not: P_true departs from P far beyond sampling error
    assert np.max(np.abs(c - exact.filter_cov) / sd) > 10
    for mean_sq, inverse, mu, cov, what in (
        (stats.mean_nees, np.linalg.inv(exact.filter_cov), m, c, "NEES"),
        (stats.mean_nis, np.linalg.inv(exact.innovation_cov), exact.moments.mean_residual, exact.moments.residual_cov, "NIS"),
    ):
        wc = inverse @ cov
        spread = 2 * np.einsum("kij,kji->k", wc, wc) + 4 * np.einsum("ka,kab,kb->k", mu, wc @ inverse, mu)
        expected = np.einsum("kij,kji->k", inverse, cov + mu[:, :, None] * mu[:, None, :])
        assert np.allclose(expected, exact.mean_nees if what == "NEES" else exact.mean_nis, rtol=1e-12)
        _assert_within((mean_sq - expected) / np.sqrt(spread / N), what)
    raw = exact.moments.residual_second_moment
    own = np.einsum("kaka->ka", raw)
    sd_pairs = np.sqrt((own[:, :, None, None] * own[None, None] + raw**2) / N)
    k, p = own.shape
    lower = np.tril(np.ones((k, k), dtype=bool), -1)
    z = ((stats.residual_second_moment - raw) / sd_pairs).transpose(0, 2, 1, 3)[lower]
    _assert_within(z, "E[r_k r_j^T]")
    cross = exact.moments.error_estimate
    est = np.diagonal(stats.estimate_second_moment, axis1=1, axis2=2)
    err = np.diagonal(stats.error_second_moment, axis1=1, axis2=2)
    sd_cross = np.sqrt((err[:, :, None] * est[:, None, :] + cross**2) / N)
    _assert_within((stats.error_estimate - cross) / sd_cross, "E[e xhat^T]")
