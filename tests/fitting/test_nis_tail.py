"""The NIS tail check of a fit's adequacy: the fit forces the mean NIS to p, not the share of NIS in the
chi-square tail, so a log with heavy-tailed GNSS errors is not adequate even where the mean-NIS and
whiteness tests pass."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import kalcal
from kalcal.fitting.nis_tail import ALPHA, TAIL, nis_tail

HEAVY = {"truth.gps_outlier_rate": 0.05, "truth.gps_outlier_std": 10.0}  # 5% of fixes with 10 m errors, 1 m otherwise


def test_the_tail_bounds_are_the_binomial_quantiles_and_gaussian_innovations_pass():
    normalized = np.random.default_rng(0).standard_normal((2000, 2))
    tail = nis_tail(normalized)
    assert tail.threshold == pytest.approx(stats.chi2.isf(TAIL, 2))
    assert tail.upper == stats.binom.isf(ALPHA / 2, 2000, TAIL) and tail.lower == stats.binom.ppf(ALPHA / 2, 2000, TAIL)
    assert tail.passed and tail.sentence() == ""


def test_student_t_innovations_of_unit_variance_fail_the_tail_though_their_mean_nis_is_p():
    rng = np.random.default_rng(1)
    normalized = rng.standard_t(3, (2000, 2)) / np.sqrt(3.0)  # t(3) has variance 3
    normalized /= np.sqrt(np.mean(normalized**2))  # mean NIS exactly 2, as at a fit's maximum
    tail = nis_tail(normalized)
    assert not tail.passed and tail.count > tail.upper and "heavier-tailed than Gaussian" in tail.sentence()


def test_a_fit_is_adequate_on_a_clean_log_and_not_on_one_with_heavy_tailed_gps_noise():
    clean = kalcal.simulate("accel-gps", seed=1, settings={"scenario.duration": 120})
    fit = kalcal.fit("accel-gps", imu=clean.logs["imu"], gps=clean.logs["gps"])
    assert fit.adequate and fit.diagnostics["nis_tail"]["passed"], fit.adequacy
    heavy = kalcal.simulate("accel-gps", seed=1, settings={"scenario.duration": 120, **HEAVY})
    fit = kalcal.fit("accel-gps", imu=heavy.logs["imu"], gps=heavy.logs["gps"])
    assert fit.diagnostics["mean_nis"] == pytest.approx(2.0, abs=1e-4)  # forced by the fit
    assert fit.diagnostics["consistent"]  # mean NIS and whiteness pass: they alone would call it adequate
    assert not fit.adequate and not fit.diagnostics["nis_tail"]["passed"]
    assert "heavier-tailed than Gaussian" in fit.adequacy and "candidates:" in fit.adequacy
