"""The prediction-error likelihood against scipy's multivariate normal density, fix by fix."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from kalcal.core.likelihood import innovation_loglik


def test_innovation_loglik_leaves_out_nan_rows_and_skipped_fixes():
    rng = np.random.default_rng(2)
    a = rng.standard_normal((6, 2, 2))
    s = a @ np.swapaxes(a, 1, 2) + np.eye(2)
    r = rng.standard_normal((6, 2))
    each = [stats.multivariate_normal(np.zeros(2), s[k]).logpdf(r[k]) for k in range(6)]
    assert np.isclose(innovation_loglik(r, s), sum(each), rtol=1e-12)
    r[2] = np.nan
    assert np.isclose(innovation_loglik(r, s, skip=1), sum(each) - each[0] - each[2], rtol=1e-12)


def test_innovation_loglik_of_three_components():
    rng = np.random.default_rng(3)
    a = rng.standard_normal((4, 3, 3))
    s = a @ np.swapaxes(a, 1, 2) + np.eye(3)
    r = rng.standard_normal((4, 3))
    want = sum(stats.multivariate_normal(np.zeros(3), s[k]).logpdf(r[k]) for k in range(4))
    assert np.isclose(innovation_loglik(r, s), want, rtol=1e-12)


def test_innovation_loglik_refuses_mismatched_shapes_and_a_negative_skip():
    with pytest.raises(ValueError, match="innovation_cov"):
        innovation_loglik(np.zeros((3, 2)), np.zeros((3, 3, 3)))
    with pytest.raises(ValueError, match="skip"):
        innovation_loglik(np.zeros((3, 2)), np.broadcast_to(np.eye(2), (3, 2, 2)), skip=-1)
