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
    assert np.array_equal(distributions.normal_cdf(X), stats.norm.cdf(X), equal_nan=True)
    assert np.array_equal(distributions.normal_ppf(P), stats.norm.ppf(P), equal_nan=True)


def test_the_calibration_gates_are_the_quantiles_they_were():
    # the two-sided z of the calibration's bias-conflict and tracking tests was special.ndtri(0.5 + c / 2)
    # in their own modules; through normal_ppf it is the same number to the bit
    from scipy import special

    for confidence in (0.9, 0.95, 0.99, 0.997):
        assert distributions.normal_ppf(0.5 + confidence / 2) == special.ndtri(0.5 + confidence / 2)


def test_no_module_computes_its_own_quantile():
    # every normal and chi-square quantile and tail of the package comes from kalcal.stats.distributions:
    # no other module's code (docstrings aside: the syntax tree) calls scipy's for them
    import ast
    from pathlib import Path

    import kalcal

    own = {"ndtri", "ndtr", "chdtri", "chdtr", "chdtrc", "gammaincinv", "gammaincc", "stdtr"}
    package = Path(kalcal.__file__).resolve().parent
    found = []
    for path in sorted(package.rglob("*.py")):
        if path.name == "distributions.py":
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Attribute) and (
                node.attr in own or (node.attr in {"ppf", "isf", "cdf", "sf"} and getattr(node.value, "attr", "") in {"norm", "chi2"})
            ):
                found.append(f"{path.relative_to(package)}:{node.lineno}: .{node.attr}")
            elif isinstance(node, ast.ImportFrom) and node.module in {"scipy.special", "scipy.stats"}:
                names = {alias.name for alias in node.names}
                if names & (own | {"norm", "chi2"}):
                    found.append(f"{path.relative_to(package)}:{node.lineno}: from {node.module} import {sorted(names)}")
    assert not found, found


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
