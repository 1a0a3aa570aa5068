"""A fit read as a statsmodels fit: params, bse, conf_int at any level, llf/aic/bic/nobs, summary, the HTML.

The intervals are checked on log-likelihoods that are exactly quadratic on the search's scale, where the
observed information is known in closed form: ln L = -(ln x - ln 2)^2 / (2 0.2^2) for a positive setting
(se of ln x: 0.2) and ln L = -(y - 1)^2 / (2 0.1^2) for a linear one (se of y: 0.1).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from kalcal.errors import KalcalError
from kalcal.fitting.mle import Free, maximize
from kalcal.fitting.result import FitParameter, FitResult

SE_LOG, SE_LINEAR = 0.2, 0.1


def _loglik(values):
    return (-0.5 * ((math.log(values["x"]) - math.log(2.0)) / SE_LOG) ** 2
            - 0.5 * ((values["y"] - 1.0) / SE_LINEAR) ** 2)


def _result(search, **rest) -> FitResult:
    fields = dict(fixes=40, adequate=True, adequacy="consistent", diagnostics={}, confidence=0.95)
    fields.update(rest)
    return FitResult.from_search("scale-bias", search, **fields)


@pytest.fixture(scope="module")
def quadratic():
    free = [Free("x", 1.0, 0.05, 80.0, "m"), Free("y", 0.3, -5.0, 5.0, "s", scale="linear")]
    return _result(maximize(_loglik, free, confidence=0.95))


def test_the_standard_errors_are_the_closed_form_observed_information(quadratic):
    x, y = quadratic.parameters["x"], quadratic.parameters["y"]
    assert (x.scale, y.scale) == ("log", "linear")
    # an exact quadratic: central differences give its curvature to rounding; the optimum to the search's tolerance
    assert x.se == pytest.approx(SE_LOG, rel=1e-4) and y.se == pytest.approx(SE_LINEAR, rel=1e-4)
    # bse: the value's standard error, x se(ln x) by the delta method on the log scale
    assert quadratic.bse["x"] == pytest.approx(x.value * x.se, rel=1e-12)
    assert quadratic.bse["y"] == y.se
    assert list(quadratic.params.index) == ["x", "y"] and list(quadratic.bse.index) == ["x", "y"]
    assert quadratic.params["x"] == x.value


def test_conf_int_at_the_stored_level_is_the_stored_interval(quadratic):
    ci = quadratic.conf_int()
    assert list(ci.columns) == ["lower", "upper"]
    for name, p in quadratic.parameters.items():
        assert (ci.loc[name, "lower"], ci.loc[name, "upper"]) == (p.ci_low, p.ci_high)
    pd.testing.assert_frame_equal(quadratic.conf_int(level=0.95), ci)
    pd.testing.assert_frame_equal(quadratic.conf_int(alpha=0.05), ci)


@pytest.mark.parametrize("level", [0.5, 0.9, 0.99, 0.999])
def test_conf_int_at_another_level_is_the_wald_interval_on_the_search_s_scale(quadratic, level):
    z = stats.norm.ppf((1 + level) / 2)
    x, y = quadratic.parameters["x"], quadratic.parameters["y"]
    ci = quadratic.conf_int(level=level)
    assert ci.loc["x", "lower"] == pytest.approx(math.exp(math.log(x.value) - z * x.se), rel=1e-12)
    assert ci.loc["x", "upper"] == pytest.approx(math.exp(math.log(x.value) + z * x.se), rel=1e-12)
    assert ci.loc["y", "lower"] == pytest.approx(y.value - z * y.se, rel=1e-12)
    assert ci.loc["y", "upper"] == pytest.approx(y.value + z * y.se, rel=1e-12)
    # and the same standard error gave the stored 95% interval: the other levels follow the stored one
    z95 = stats.norm.ppf(0.975)
    assert math.log(x.ci_high / x.ci_low) == pytest.approx(2 * z95 * x.se, rel=1e-9)
    assert y.ci_high - y.ci_low == pytest.approx(2 * z95 * y.se, rel=1e-9)
    pd.testing.assert_frame_equal(quadratic.conf_int(alpha=1 - level), ci)


def test_intervals_nest_by_level(quadratic):
    narrow, stored, wide = (quadratic.conf_int(level=level) for level in (0.9, 0.95, 0.99))
    assert (wide["lower"] < stored["lower"]).all() and (stored["lower"] < narrow["lower"]).all()
    assert (narrow["upper"] < stored["upper"]).all() and (stored["upper"] < wide["upper"]).all()


@pytest.mark.parametrize("arguments", [dict(level=1.0), dict(level=0.0), dict(alpha=-0.1), dict(alpha=0.05, level=0.95),
                                       dict(level=float("nan")), dict(level=True)])
def test_a_bad_level_is_a_value_error_naming_it(quadratic, arguments):
    with pytest.raises(KalcalError, match="conf_int: "):
        quadratic.conf_int(**arguments)


def test_aic_and_bic_are_their_definitions_from_llf_and_the_free_parameters(quadratic):
    k = 2  # x and y, both searched
    assert quadratic.llf == quadratic.loglik == pytest.approx(0.0, abs=1e-6)
    assert quadratic.nobs == 40
    assert quadratic.aic == pytest.approx(2 * k - 2 * quadratic.llf, rel=0, abs=1e-12)
    assert quadratic.bic == pytest.approx(k * math.log(40) - 2 * quadratic.llf, rel=0, abs=1e-12)


def test_a_likelihood_ratio_interval_holds_at_its_own_level_only():
    free = [Free("x", 1.0, 0.05, 80.0, "m"), Free("y", 0.3, -5.0, 5.0, "s", scale="linear")]
    profiled = _result(maximize(_loglik, free, confidence=0.95, profile=True))
    assert profiled.interval_method == "profile"
    assert all(p.se is None for p in profiled.parameters.values())
    assert profiled.bse.isna().all()
    ci = profiled.conf_int()
    assert ci.loc["x", "lower"] == profiled.parameters["x"].ci_low
    with pytest.raises(KalcalError, match=r"profile-likelihood interval of x, y holds at the fit's level 0.95 only"):
        profiled.conf_int(level=0.9)


def _synthetic(note: str = "", adequacy: str = "consistent") -> FitResult:
    parameters = {
        "filter.a": FitParameter("filter.a", 2.0, 1.5, 2.6, "m", 1.0, scale="log", se=0.14),
        "filter.b": FitParameter("filter.b", 0.01, 0.0, 0.03, "m/s", 0.02, at_bound=True, note=note),
        "filter.c": FitParameter("filter.c", None, None, None, "s", 0.0, identified=False, note="unidentified"),
    }
    return FitResult("accel-gps", parameters, loglik=-10.0, aic=26.0, fixes=50, converged=True,
                     interval_method="observed-information", adequate=True, adequacy=adequacy, diagnostics={}, df_model=3)


def test_an_interval_consistent_with_0_is_refused_at_another_level_and_unidentified_is_nan():
    fit = _synthetic()
    ci = fit.conf_int()
    assert (ci.loc["filter.b", "lower"], ci.loc["filter.b", "upper"]) == (0.0, 0.03)
    assert ci.loc["filter.c"].isna().all() and np.isnan(fit.params["filter.c"]) and np.isnan(fit.bse["filter.b"])
    with pytest.raises(KalcalError, match=r"likelihood-ratio interval of filter.b holds at the fit's level 0.95 only"):
        fit.conf_int(level=0.9)
    assert fit.bic == pytest.approx(3 * math.log(50) + 20.0, rel=1e-15)


def test_summary_is_a_text_table_with_the_headline_numbers_and_str_is_it():
    fit = _synthetic(note="consistent with 0: 95% upper limit 0.03 m/s")
    text = fit.summary()
    assert str(fit) == text
    for piece in ("kalcal fit accel-gps", "log-likelihood: -10", "AIC: 26", f"BIC: {fit.bic:.6g}", "observations: 50",
                  "free parameters: 3", "[0.025", "0.975]", "filter.a", "2.6", "0.28",
                  "[1] filter.b: consistent with 0"):
        assert piece in text, piece
    assert "FitResult(accel-gps: filter.a=2, filter.b=0.01, filter.c=unidentified" in repr(fit)


def test_the_html_repr_holds_the_headline_numbers_and_escapes_text():
    fit = _synthetic(note="<script>alert(1)</script>", adequacy="a & b < c")
    page = fit._repr_html_()
    assert "<script>" not in page and "&lt;script&gt;" in page and "a &amp; b &lt; c" in page
    for number in ("2", "1.5", "2.6", "0.28", "-10", "26", f"{fit.bic:.4g}", "50"):
        assert f">{number}<" in page or f" {number}," in page or f" {number} " in page, number


def test_save_without_the_run_says_why():
    with pytest.raises(KalcalError, match="save: "):
        _synthetic().save("never-written")
