"""The NIS tail check on a gated fit: the gate cuts off the very tail the check counts, so it does not
apply there (the reason is given), and a long clean gated log is not failed for it."""

from __future__ import annotations

import numpy as np
from scipy import stats

from kalcal.scenarios.accel_gps.fit import fit_accel_gps
from kalcal.fitting.nis_tail import lower_side_fixes, nis_tail
from kalcal.scenarios import build_scenario

from tests.fitting.fake_log import FakeLog

KEY = "filter.gps_position_std"


def gaussian_log(fixes, seed=0):
    normalized = np.random.default_rng(seed).standard_normal((fixes, 2))
    loglik = lambda v: -fixes * (np.log(v[KEY]) + 0.5 / v[KEY] ** 2)  # noqa: E731  (maximum at 1)
    return FakeLog(loglik, normalized, {KEY: 0.7})


def test_a_long_clean_gated_fit_is_not_failed_by_the_tail_check_and_says_why_it_does_not_apply():
    fixes = 12_000  # above the ~7,600 where the check's lower bound reaches 1
    log = gaussian_log(fixes)
    gated = log.normalized[np.sum(log.normalized**2, axis=1) <= stats.chi2.ppf(0.999, 2)]
    assert not nis_tail(gated).passed  # what the gated fit used to report: 0 fixes in the tail, "lighter-tailed"
    result = fit_accel_gps(log, build_scenario("accel-gps", None, []), [KEY], gate=0.999)
    tail = result.diagnostics["nis_tail"]
    assert tail["applies"] is False and tail["passed"] is None
    assert "not applied with --gate 0.999" in tail["reason"] and "count would be 0" in tail["reason"]
    assert "lighter-tailed" not in result.adequacy
    assert result.adequate, result.adequacy


def test_a_gate_above_the_tails_quantile_is_said_to_cut_the_tail_off():
    log = gaussian_log(2000)
    result = fit_accel_gps(log, build_scenario("accel-gps", None, []), [KEY], gate=0.9999)
    assert "cut off at the gate" in result.diagnostics["nis_tail"]["reason"]


def test_an_ungated_fit_applies_the_check():
    result = fit_accel_gps(gaussian_log(2000), build_scenario("accel-gps", None, []), [KEY])
    assert result.diagnostics["nis_tail"]["applies"] is True and result.diagnostics["nis_tail"]["passed"]


def test_the_lower_side_acts_from_about_7600_fixes_and_the_quantile_is_named():
    fixes = lower_side_fixes()
    assert stats.binom.ppf(0.0005, fixes, 0.001) == 1 and stats.binom.ppf(0.0005, fixes - 1, 0.001) == 0
    assert 7500 < fixes < 7700  # docs/fit.md: "above about 7,600 fixes"
    few = np.zeros((fixes - 1, 2))
    assert nis_tail(few).lower == 0 and nis_tail(few).passed  # none in the tail: only the upper side acts
    assert not nis_tail(np.zeros((fixes, 2))).passed
    sentence = nis_tail(np.zeros((fixes, 2))).sentence()
    assert "above the chi-square 99.9% quantile (13.8)" in sentence and "0%" not in sentence.replace("99.9%", "")
