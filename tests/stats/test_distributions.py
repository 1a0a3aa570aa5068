"""The checks' normal and chi-square functions equal scipy.stats's to the bit, edges included."""

import ast

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
    assert np.array_equal(distributions.normal_cdf(X), stats.norm.cdf(X), equal_nan=True)
    assert np.array_equal(distributions.normal_ppf(P), stats.norm.ppf(P), equal_nan=True)


def test_the_calibration_gates_are_the_quantiles_they_were():
    # the two-sided z of the calibration's bias-conflict and tracking tests was special.ndtri(0.5 + c / 2)
    # in their own modules; through normal_ppf it is the same number to the bit
    from scipy import special

    for confidence in (0.9, 0.95, 0.99, 0.997):
        assert distributions.normal_ppf(0.5 + confidence / 2) == special.ndtri(0.5 + confidence / 2)


#: scipy.special's functions behind the normal, chi-square and t quantiles and tails
_SPECIAL = {"ndtri", "ndtr", "chdtri", "chdtr", "chdtrc", "gammaincinv", "gammaincc", "stdtr", "bdtr", "bdtrc", "bdtri"}
#: a distribution's quantile or tail, as scipy.stats's distributions name them
_TAILS = {"ppf", "isf", "cdf", "sf", "logcdf", "logsf"}


def own_quantile_calls(source: str) -> list[str]:
    """Where a module's code (docstrings aside: the syntax tree) computes a quantile, a tail or a binomial
    test itself: scipy.special's functions for them, ``<anything>.<dist>.(ppf|isf|cdf|sf)`` of any
    distribution, ``binomtest``, or any import of scipy.stats (kalcal.stats.distributions alone imports it)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Attribute):
            if node.attr in _SPECIAL | {"binomtest", "binom_test"}:
                found.append(f"{node.lineno}: .{node.attr}")
            elif node.attr in _TAILS and isinstance(node.value, (ast.Attribute, ast.Name)):
                owner = node.value.attr if isinstance(node.value, ast.Attribute) else node.value.id
                if owner not in {"self", "cls"} and not owner.startswith("_"):
                    found.append(f"{node.lineno}: {owner}.{node.attr}")
        elif isinstance(node, ast.Name) and node.id in {"binomtest"}:
            found.append(f"{node.lineno}: {node.id}")
        elif isinstance(node, ast.ImportFrom):
            names = {alias.name for alias in node.names}
            if node.module == "scipy.stats" or node.module and node.module.startswith("scipy.stats."):
                found.append(f"{node.lineno}: from {node.module} import {sorted(names)}")
            elif node.module == "scipy" and "stats" in names:
                found.append(f"{node.lineno}: from scipy import stats")
            elif node.module == "scipy.special" and names & _SPECIAL:
                found.append(f"{node.lineno}: from scipy.special import {sorted(names & _SPECIAL)}")
        elif isinstance(node, ast.Import) and any(a.name == "scipy.stats" or a.name.startswith("scipy.stats.") for a in node.names):
            found.append(f"{node.lineno}: import scipy.stats")
    return found


def test_no_module_computes_its_own_quantile():
    # every quantile, tail and binomial test of the package comes from kalcal.stats.distributions
    from pathlib import Path

    import kalcal

    package = Path(kalcal.__file__).resolve().parent
    found = [
        f"{path.relative_to(package)}:{where}"
        for path in sorted(package.rglob("*.py"))
        if path.relative_to(package).as_posix() != "stats/distributions.py"
        for where in own_quantile_calls(path.read_text(encoding="utf-8"))
    ]
    assert not found, found


@pytest.mark.parametrize(
    "source",
    [
        "from scipy import stats\nx = stats.binom.ppf(0.1, 10, 0.5)\n",
        "def f():\n    from scipy import stats\n    return stats.binomtest(3, 10, 0.5).pvalue\n",
        "import scipy.stats\nx = scipy.stats.binom.isf(0.1, 10, 0.5)\n",
        "from scipy.stats import poisson\nx = poisson.sf(3, 1.0)\n",
        "from scipy.stats import binomtest\n",
        "import scipy.special as sp\nx = sp.bdtrc(3, 10, 0.5)\n",
        "from scipy.special import ndtri\n",
        "x = some.norm.cdf(1.0)\n",
        "x = gamma.ppf(0.5, 2.0)\n",
    ],
)
def test_the_walk_catches_each_own_quantile(source):
    assert own_quantile_calls(source)


def test_the_walk_leaves_the_packages_own_calls_alone():
    assert not own_quantile_calls("from kalcal.stats.distributions import binom_ppf, chi2_isf\nx = binom_ppf(0.1, 10, 0.5)\n")


def test_binomial_functions_are_scipy_stats():
    assert distributions.binom_ppf(0.005, 1000, 0.001) == stats.binom.ppf(0.005, 1000, 0.001)
    assert distributions.binom_isf(0.005, 1000, 0.001) == stats.binom.isf(0.005, 1000, 0.001)
    assert distributions.binom_cdf(3, 40, 0.15) == stats.binom.cdf(3, 40, 0.15)
    assert distributions.binom_sf(8, 40, 0.15) == stats.binom.sf(8, 40, 0.15)
    assert distributions.binom_test(7, 1000, 0.001) == stats.binomtest(7, 1000, 0.001).pvalue
    assert distributions.binom_test(0, 0, 0.001) == 1.0


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


def test_student_t_tails_equal_scipy_stats():
    from scipy import stats

    from kalcal.stats.distributions import t_isf, t_sf

    for dof in (1, 2, 5, 30):
        q = np.array([0.4, 0.05, 0.005, 1e-6])
        np.testing.assert_allclose(t_isf(q, dof), stats.t.isf(q, dof), rtol=1e-12)
        np.testing.assert_allclose(t_sf(t_isf(q, dof), dof), q, rtol=1e-10)
    assert abs(float(t_isf(0.005, 2)) - 9.925) < 1e-3  # the 99% two-sided quantile with 3 groups
