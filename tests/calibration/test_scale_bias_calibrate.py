"""Calibrating a log of the scale/bias scenario: a and b recovered within the uncertainty the filter states.

Statistical checks use fixed seeds and bounds from theory: a normalized error z = (estimate - truth) / std
is N(0, 1) for a correct filter (exactly for theta, to first order for a and b by the delta method), so
over M seeds the mean of z lies within k / sqrt(M) and the variance within chi-square(M - 1) / (M - 1)
quantiles; k and the quantiles are held to a family-wise error of 1e-4.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from kalcal.scenarios.scale_bias.calibration import calibrate_scale_bias
from kalcal.errors import DataError
from kalcal.scenarios import build_scenario
from kalcal.scenarios.scale_bias.theta import scale_bias_from_theta
from kalcal.scenarios.scale_bias.simulation import sample_scale_bias
from tests._helpers import bonferroni_k

SEEDS = range(100, 150)


def _calibrated(scenario, seed: int):
    samples = sample_scale_bias(scenario, np.random.default_rng(seed), 1)
    result = calibrate_scale_bias(scenario, samples.time, samples.reference[0], samples.sensor[0])
    return samples, result


@pytest.fixture(scope="module")
def normalized_errors():
    scenario = build_scenario("scale-bias")
    z_ab, z_theta, nees = [], [], []
    for seed in SEEDS:
        samples, result = _calibrated(scenario, seed)
        a, b, cov = result.scale_bias()
        true_a, true_b = scale_bias_from_theta(samples.theta[0, -1])
        z_ab.append([(a - true_a) / np.sqrt(cov[0, 0]), (b - true_b) / np.sqrt(cov[1, 1])])
        error = samples.theta[0, -1] - result.theta[-1]
        z_theta.append(error / result.std[-1])
        nees.append(error @ np.linalg.solve(result.covariance[-1], error))
    return np.array(z_ab), np.array(z_theta), np.array(nees)


def test_recovers_a_and_b_within_four_sigma_on_several_seeds(normalized_errors):
    z_ab, _, _ = normalized_errors
    assert np.all(np.abs(z_ab[:8]) < 4.0), z_ab[:8]


@pytest.mark.parametrize("which", ["a_b", "theta"])
def test_normalized_errors_have_unit_normal_moments(normalized_errors, which):
    z = normalized_errors[0] if which == "a_b" else normalized_errors[1]
    m = z.shape[0]
    # 2 means and 2 variances in each family
    k = bonferroni_k(4)
    low, high = stats.chi2.ppf(1e-4 / 8, m - 1) / (m - 1), stats.chi2.isf(1e-4 / 8, m - 1) / (m - 1)
    assert np.all(np.abs(z.mean(axis=0)) <= k / np.sqrt(m)), z.mean(axis=0)
    variance = z.var(axis=0, ddof=1)
    assert np.all((variance >= low) & (variance <= high)), (variance, low, high)


def test_sum_of_nees_is_chi_square(normalized_errors):
    nees = normalized_errors[2]
    dof = 2 * nees.size
    assert stats.chi2.ppf(5e-5, dof) <= nees.sum() <= stats.chi2.isf(5e-5, dof)


def test_delta_method_and_summary_quantities():
    scenario = build_scenario("scale-bias")
    _, result = _calibrated(scenario, 3)
    theta, cov = result.theta[-1], result.covariance[-1]
    a, b, ab_cov = result.scale_bias()
    assert a == pytest.approx(1 - 1 / theta[0], rel=1e-14)
    assert b == pytest.approx(theta[1] / theta[0], rel=1e-14)
    # var(a) = P11 / theta1^4;  var(b) = (theta2^2 P11 - 2 theta1 theta2 P12 + theta1^2 P22) / theta1^4
    t1, t2 = theta
    assert ab_cov[0, 0] == pytest.approx(cov[0, 0] / t1**4, rel=1e-12)
    assert ab_cov[1, 1] == pytest.approx((t2**2 * cov[0, 0] - 2 * t1 * t2 * cov[0, 1] + t1**2 * cov[1, 1]) / t1**4, rel=1e-12)
    assert result.samples_used == 300
    assert 0.8 < result.mean_nis < 1.2  # 300 chi-square(1) terms: sd of the mean 0.08


def test_missing_samples_are_skipped_and_counted():
    scenario = build_scenario("scale-bias")
    samples = sample_scale_bias(scenario, np.random.default_rng(4), 1)
    reference, sensor = samples.reference[0].copy(), samples.sensor[0].copy()
    reference[10], sensor[20:25] = np.nan, np.nan
    result = calibrate_scale_bias(scenario, samples.time, reference, sensor)
    assert result.samples_used == 294
    assert np.all(np.isfinite(result.theta))


def test_a_sensor_that_does_not_follow_the_reference_is_a_data_error():
    scenario = build_scenario("scale-bias")
    samples = sample_scale_bias(scenario, np.random.default_rng(4), 1)
    with pytest.raises(DataError, match="log.csv: the estimated theta1 = .* is not positive"):
        calibrate_scale_bias(scenario, samples.time, samples.reference[0], -samples.sensor[0], source="log.csv")
    with pytest.raises(DataError, match="log.csv: no sample has both"):
        calibrate_scale_bias(scenario, samples.time, np.full(300, np.nan), samples.sensor[0], source="log.csv")


def test_nis_bounds_are_the_packages_chi_square_mean_bounds(monkeypatch):
    """The mean NIS's bounds come from kalcal.stats.bounds, the one place of the package's chi-square bounds:
    the calibration's answer is chi2_mean_bounds's, whatever that returns."""
    from kalcal.scenarios.scale_bias import calibration
    from kalcal.stats.bounds import chi2_mean_bounds

    result = calibration.ScaleBiasCalibration(
        time=np.arange(3.0), theta=np.zeros((3, 2)), covariance=np.zeros((3, 2, 2)), residual=np.zeros(3),
        innovation_var=np.ones(3), used=np.array([False, True, True]),
    )
    assert result.nis_bounds(0.99) == chi2_mean_bounds(0.99, 1, 2, 2)
    monkeypatch.setattr(calibration, "chi2_mean_bounds", lambda confidence, comparisons, dof, count: (dof, count + confidence))
    assert result.nis_bounds(0.99) == (2, 2.99)
