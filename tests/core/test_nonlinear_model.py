"""The nonlinear model's container, its Jacobians (sympy, jax, checked finite differences) and the model file's loader."""

from __future__ import annotations

import dataclasses
import importlib.util

import numpy as np
import pytest

from kalcal.core import xmath as xm
from kalcal.core.nonlinear import finite_difference_jacobian, load_nonlinear_model
from kalcal.errors import ConfigError
from kalcal.models.settings import SettingError
from tests.core._nonlinear_models import EXAMPLE, range_bearing, range_bearing_jacobian

BEACON = np.array([3.0, -4.0])


def _states(n=50):
    rng = np.random.default_rng(3)
    model = range_bearing()
    return model, model.x0 + rng.standard_normal((n, 4)) * np.sqrt(np.diag(model.p0)) * 5


@pytest.mark.parametrize(
    "method",
    ["sympy", "finite", pytest.param("jax", marks=pytest.mark.skipif(importlib.util.find_spec("jax") is None, reason="the optional extra kalcal[jax] is not installed"))],
)
def test_each_jacobian_method_matches_the_hand_written_jacobian(method):
    model, x = _states()
    model = dataclasses.replace(model, jacobian=method)
    tol = 1e-7 if method == "finite" else 1e-12
    np.testing.assert_allclose(model.measurement_jacobian(x, BEACON), range_bearing_jacobian(x, BEACON), rtol=tol, atol=tol * 1e-2)
    f_jac = np.broadcast_to(np.array([[1, 0, model.dt, 0], [0, 1, 0, model.dt], [0, 0, 1, 0], [0, 0, 0, 1.0]]), (x.shape[0], 4, 4))
    np.testing.assert_allclose(model.transition_jacobian(x), f_jac, rtol=tol, atol=tol)
    assert model.jacobians.method == method


def test_the_default_is_sympy_and_explicit_jacobians_are_used_when_given():
    model = range_bearing()
    assert model.jacobians.method == "sympy"
    explicit = dataclasses.replace(model, h_jacobian=lambda x, data: np.full((x.shape[0], 2, 4), 7.0))
    _, x = _states(3)
    assert np.all(explicit.measurement_jacobian(x, BEACON) == 7.0)


def test_a_function_that_cannot_take_symbols_falls_back_to_finite_differences_and_says_why():
    model = range_bearing()
    numpy_only = dataclasses.replace(
        model, h=lambda x, data: np.stack([np.hypot(x[:, 0] - data[..., 0], x[:, 1] - data[..., 1]), np.arctan2(x[:, 1] - data[..., 1], x[:, 0] - data[..., 0])], axis=-1)
    )
    assert numpy_only.jacobians.method == "finite"
    assert "sympy" in numpy_only.jacobians.reason
    _, x = _states()
    np.testing.assert_allclose(numpy_only.measurement_jacobian(x, BEACON), range_bearing_jacobian(x, BEACON), rtol=1e-7, atol=1e-9)


def test_finite_differences_warn_or_refuse_where_the_two_steps_disagree():
    x = np.array([[1e-6, 1.0], [2.0, 1.0]])  # |x_0| has a kink at 0, within the first realization's steps
    kink = lambda s: xm.stack([xm.abs(s[:, 0]) + s[:, 1] ** 2])  # noqa: E731
    with pytest.warns(RuntimeWarning, match="realization 0"):
        finite_difference_jacobian(kink, x, np.ones(2))
    with pytest.raises(ConfigError, match="disagree"):
        finite_difference_jacobian(kink, x, np.ones(2), check="raise")
    smooth = finite_difference_jacobian(kink, x[1:], np.ones(2), check="raise")
    np.testing.assert_allclose(smooth[0], [[1.0, 2.0]], rtol=1e-9)


def test_bad_settings_are_refused_naming_the_field():
    model = range_bearing()
    with pytest.raises(SettingError, match="r: expected a positive definite"):
        dataclasses.replace(model, r=np.zeros((2, 2)))
    with pytest.raises(SettingError, match="state_names: expected 4 names"):
        dataclasses.replace(model, state_names=("px",))
    with pytest.raises(SettingError, match="jacobian"):
        dataclasses.replace(model, jacobian="magic")
    with pytest.raises(ConfigError, match=r"data: the model takes 2 values"):
        model.measure(model.x0[None])


def test_the_loader_reads_model_and_truth_filter_files(tmp_path):
    loaded = load_nonlinear_model(EXAMPLE)
    assert loaded.truth is loaded.filter and loaded.filter.state_names == ("px", "py", "vx", "vy")
    pair = tmp_path / "pair.py"
    pair.write_text(
        f"import dataclasses, importlib.util\n"
        f"spec = importlib.util.spec_from_file_location('rb', {str(EXAMPLE)!r})\n"
        f"rb = importlib.util.module_from_spec(spec); spec.loader.exec_module(rb)\n"
        f"truth = rb.MODEL\nfilter = dataclasses.replace(rb.MODEL, r=rb.MODEL.r * 2)\n"
    )
    loaded = load_nonlinear_model(pair)
    np.testing.assert_array_equal(loaded.filter.r, 2 * loaded.truth.r)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("x = 1\n", "defines neither MODEL nor truth and filter"),
        ("MODEL = 3\n", "MODEL: expected a kalcal NonlinearModel, got int"),
        ("truth = None\n", "defines neither MODEL nor filter"),
        ("raise RuntimeError('boom')\n", "failed to run: RuntimeError: boom"),
    ],
)
def test_the_loader_refuses_in_one_line_naming_the_file(tmp_path, text, message):
    path = tmp_path / "model.py"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message) as caught:
        load_nonlinear_model(path)
    assert str(path) in str(caught.value) and "\n" not in str(caught.value)


def test_the_loader_refuses_a_missing_file(tmp_path):
    with pytest.raises(ConfigError, match="no such file"):
        load_nonlinear_model(tmp_path / "absent.py")


def test_the_examples_bearings_stay_far_from_the_arctan2_cut():
    """docs/nonlinear.md: the example's bearings stay within (-0.5, 2.5) rad, so no wrap is needed."""
    from tests.core._nonlinear_models import simulate

    model = range_bearing()
    _, z = simulate(model, 500, 100, np.random.default_rng(4), np.zeros(2))
    assert -0.5 < z[..., 1].min() and z[..., 1].max() < 2.5
