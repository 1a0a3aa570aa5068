"""The printer of a model's compiled functions (kalcal.core.nonlinear_codegen): a power of half an odd
integer is printed as a product with a root (a compiled ``**`` of a float exponent is a call of pow),
and the printed text computes the power to rounding."""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy

from kalcal.core.nonlinear_codegen import _printer, model_source
from kalcal.scenarios import build_scenario

x, y = sympy.symbols("x y")


@pytest.mark.parametrize("exponent", [sympy.Rational(3, 2), sympy.Rational(-3, 2), sympy.Rational(5, 2),
                                      sympy.Rational(-7, 2)])
def test_half_integer_power_is_a_root_and_a_product_equal_to_rounding(exponent):
    expr = 9.80665 / (x**2 + y**2 + 1) ** exponent
    text = _printer().doprint(expr)
    assert "**(" not in text and "math.sqrt" in text, text
    for xv, yv in [(0.01, -0.02), (0.3, 0.7), (2.0, 5.0)]:
        got = eval(text, {"math": math, "x": xv, "y": yv})  # noqa: S307  the printer's own text
        want = 9.80665 / (xv**2 + yv**2 + 1) ** float(exponent)
        assert got == pytest.approx(want, rel=8 * np.finfo(float).eps)


def test_roots_and_integer_powers_print_as_before():
    printer = _printer()
    assert printer.doprint(1 / sympy.sqrt(x)) == "1/math.sqrt(x)"
    assert printer.doprint(x**2) == "x**2"


def test_the_pose_models_printed_functions_call_no_pow():
    """imu-3axis's H (the derivative of a normalized direction) has a power -3/2: printed without ``**(``."""
    text = model_source(build_scenario("imu-3axis", None, []).loaded.filter, "m")
    assert "**(" not in text
