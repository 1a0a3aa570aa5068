"""The search's fallback to the profile where the observed information is not positive definite, judged at
the range's ends (a ridge), and the evaluations of every restarted search counted."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from kalcal.fitting import mle

DROP = stats.chi2.ppf(0.95, 1) / 2


def _not_positive_definite(monkeypatch):
    monkeypatch.setattr(mle, "_hessian", lambda f, u, index: -np.eye(len(index)))


def test_on_a_ridge_the_profile_that_never_falls_makes_the_parameter_unidentified_not_a_traceback(monkeypatch):
    # log L depends on a b only: the slice along a falls (b held), the profile (b re-maximized) is flat
    def loglik(values):
        return float(-50.0 * np.log(values["a"] * values["b"]) ** 2)

    _not_positive_definite(monkeypatch)
    fit = mle.maximize(loglik, [mle.Free("a", 1.0, 1e-3, 1e3), mle.Free("b", 1.0, 1e-3, 1e3)])
    a = fit.parameters["a"]
    assert not a.identified and a.value is None and a.ci_low is None and a.ci_high is None
    assert "unidentified along the profile" in a.note


def _one_sided(values):
    """A ridge in u_a + u_b, and a fall in u_a > 0 only: the profile along a falls above 0, not below."""
    ua, ub = np.log(values["a"]), values["b"]
    return float(-50.0 * (ua + ub) ** 2 - 0.125 * max(ua, 0.0) ** 2)


def test_where_the_profile_falls_on_one_side_only_the_other_has_no_limit(monkeypatch):
    _not_positive_definite(monkeypatch)
    free = [mle.Free("a", 1.0, 1e-3, 1e3), mle.Free("b", 0.0, -10.0, 10.0, scale="linear")]
    fit = mle.maximize(_one_sided, free, restarts=0)
    a = fit.parameters["a"]
    assert a.identified and a.at_bound and a.ci_low == 0.0  # log scale: consistent with 0 along the profile
    # the upper limit: 0.125 u^2 = 1.92
    assert np.log(a.ci_high) == pytest.approx(np.sqrt(DROP / 0.125), abs=2e-3)
    assert "profile likelihood" in a.note and "consistent with 0 along the profile" in a.note


def test_a_linear_parameter_whose_profile_does_not_fall_below_has_no_lower_limit(monkeypatch):
    def loglik(values):  # the same surface with a on a linear scale: u_a = a
        return _one_sided({"a": np.exp(values["a"]), "b": values["b"]})

    _not_positive_definite(monkeypatch)
    free = [mle.Free("a", 0.0, -7.0, 7.0, scale="linear"), mle.Free("b", 0.0, -10.0, 10.0, scale="linear")]
    a = mle.maximize(loglik, free, restarts=0).parameters["a"]
    assert a.identified and not a.at_bound and a.ci_low is None
    assert a.ci_high == pytest.approx(np.sqrt(DROP / 0.125), abs=2e-3)
    assert "no limit within the search range" in a.note


def test_a_restarted_search_counts_the_evaluations_of_every_search():
    calls = []

    def loglik(values):  # two maxima: the search from 0.1 stops at the local one, the curve finds 0.3
        calls.append(1)
        x = values["x"]
        return float(np.log(np.exp(-((x - 0.1) ** 2) / 0.005) + 3 * np.exp(-((x - 0.3) ** 2) / 0.005) + 1e-12))

    fit = mle.maximize(loglik, [mle.Free("x", 0.1, -1.0, 1.0, scale="linear")], curve_points=41)
    assert fit.values["x"] == pytest.approx(0.3, abs=1e-3)
    assert fit.evaluations == len(calls)
