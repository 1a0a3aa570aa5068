"""The checks' normal and chi-square functions equal scipy.stats's to the bit, edges included."""


import numpy as np
import pytest
from scipy import stats

from kalcal.stats import distributions

X = np.array([-3.0, -1e-300, 0.0, 1e-12, 0.3, 1.0, 2.5, 7.0, 40.0, 300.0, 1e4, np.inf, -np.inf, np.nan])
P = np.array([-0.1, 0.0, 1e-300, 1e-20, 1e-9, 0.025, 0.5, 0.975, 1 - 1e-12, 1.0, 1.1, np.nan])
DOFS = [0.5, 1, 2, 3, 10, 44_700, 1e6, 0, -1]


def test_normal_tails_equal_scipy_stats():
    assert np.array_equal(distributions.normal_sf(X), stats.norm.sf(X), equal_nan=True)
    assert np.array_equal(distributions.normal_isf(P), stats.norm.isf(P), equal_nan=True)


@pytest.mark.parametrize("dof", DOFS)
@pytest.mark.parametrize(
    ("ours", "theirs", "values"),
    [
        (distributions.chi2_cdf, stats.chi2.cdf, X),
        (distributions.chi2_sf, stats.chi2.sf, X),
        (distributions.chi2_ppf, stats.chi2.ppf, P),
        (distributions.chi2_isf, stats.chi2.isf, P),
    ],
)
def test_chi2_equals_scipy_stats(ours, theirs, values, dof):
    assert np.array_equal(ours(values, dof), theirs(values, dof), equal_nan=True)


@pytest.mark.parametrize("dof", [1, 3, 10, 1e3])
@pytest.mark.parametrize("nc", [0.1, 1.0, 30.0, 500.0])
def test_noncentral_chi2_agrees_with_scipy_stats(dof, nc):
    x = np.array([-1.0, 0.0, 0.5, 3.0, 12.0, 60.0, 800.0, 3000.0])
    np.testing.assert_allclose(distributions.ncx2_cdf(x, dof, nc), stats.ncx2.cdf(x, dof, nc), rtol=1e-9, atol=1e-13)
    np.testing.assert_allclose(distributions.ncx2_sf(x, dof, nc), stats.ncx2.sf(x, dof, nc), rtol=1e-9, atol=1e-13)
