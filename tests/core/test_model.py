"""LinearGaussianModel: validation names the field; arrays are frozen."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from kalcal.core.model import LinearGaussianModel, check_covariance
from kalcal.errors import ConfigError, KalcalError


def _valid(**changes):
    values = dict(
        phi=[[1.0, 0.1], [0.0, 1.0]],
        gamma=[[0.005], [0.1]],
        h=[[1.0, 0.0]],
        w=[[0.04]],
        v=[[0.25]],
        x0=[0.0, 1.0],
        m0=[[1.0, 0.2], [0.2, 0.5]],
        steps_per_update=5,
        sample_period=0.1,
    )
    values.update(changes)
    return LinearGaussianModel(**values)


def test_valid_model_properties():
    model = _valid()
    assert (model.state_dim, model.measurement_dim) == (2, 1)
    assert model.update_period == pytest.approx(0.5, rel=1e-15)
    assert model.phi.dtype == float and model.x0.shape == (2,)
    assert isinstance(model.steps_per_update, int)


def test_arrays_are_read_only_and_model_is_frozen():
    model = _valid()
    with pytest.raises(ValueError):
        model.phi[0, 0] = 5.0
    with pytest.raises(ValueError):
        model.x0[0] = 5.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        model.phi = np.eye(2)  # type: ignore[misc]


def test_input_arrays_are_copied():
    phi = np.array([[1.0, 0.1], [0.0, 1.0]])
    model = _valid(phi=phi)
    phi[0, 1] = 9.0
    assert model.phi[0, 1] == 0.1


@pytest.mark.parametrize(
    "field, value",
    [
        ("phi", [[1.0, 0.1, 0.0], [0.0, 1.0, 0.0]]),  # not square
        ("phi", [1.0, 2.0]),  # not a matrix
        ("gamma", [[0.005], [0.1], [0.0]]),  # rows do not match phi
        ("h", [[1.0, 0.0, 0.0]]),  # columns do not match phi
        ("w", [[0.04, 0.0], [0.0, 0.04]]),  # does not match gamma's columns
        ("v", [[0.25, 0.0], [0.0, 0.25]]),  # does not match h's rows
        ("m0", [[1.0]]),
        ("x0", [0.0, 1.0, 2.0]),
    ],
)
def test_wrong_shapes_name_the_field(field, value):
    with pytest.raises(ConfigError, match=rf"^{field}\b"):
        _valid(**{field: value})


@pytest.mark.parametrize("field", ["phi", "gamma", "h", "w", "v", "m0"])
def test_non_finite_entries_name_the_field(field):
    value = np.array(getattr(_valid(), field), dtype=float)
    value.flat[0] = np.nan
    with pytest.raises(ConfigError, match=rf"^{field}\b"):
        _valid(**{field: value})


@pytest.mark.parametrize(
    "changes, field",
    [
        (dict(m0=[[1.0, 0.2], [0.3, 0.5]]), "m0"),
        (dict(gamma=[[0.005, 0.0], [0.1, 0.0]], w=[[0.04, 0.01], [0.0, 0.04]]), "w"),
        (dict(h=[[1.0, 0.0], [0.0, 1.0]], v=[[1.0, 0.1], [0.0, 1.0]]), "v"),
    ],
)
def test_asymmetric_covariance_names_the_field(changes, field):
    with pytest.raises(ConfigError, match=rf"^{field}: .*symmetric"):
        _valid(**changes)


@pytest.mark.parametrize(
    "changes, field",
    [
        (dict(m0=[[1.0, 2.0], [2.0, 1.0]]), "m0"),  # eigenvalues 3, -1
        (dict(w=[[-0.04]]), "w"),
        (dict(v=[[-0.25]]), "v"),
    ],
)
def test_non_psd_covariance_names_the_field(changes, field):
    with pytest.raises(ConfigError, match=rf"^{field}: .*positive"):
        _valid(**changes)


def test_singular_measurement_noise_is_rejected():
    with pytest.raises(ConfigError, match=r"^v: .*positive definite"):
        _valid(h=[[1.0, 0.0], [0.0, 1.0]], v=[[1.0, 1.0], [1.0, 1.0]])


def test_singular_process_noise_and_prior_are_allowed():
    model = _valid(w=[[0.0]], m0=[[1.0, 0.0], [0.0, 0.0]])
    assert model.m0[1, 1] == 0.0


@pytest.mark.parametrize("steps", [0, -1, 2.5])
def test_steps_per_update_must_be_positive_integer(steps):
    with pytest.raises(ConfigError, match=r"^steps_per_update"):
        _valid(steps_per_update=steps)


@pytest.mark.parametrize("period", [0.0, -0.1, float("nan"), float("inf")])
def test_sample_period_must_be_positive_finite(period):
    with pytest.raises(ConfigError, match=r"^sample_period"):
        _valid(sample_period=period)


def test_config_error_is_a_value_error():
    assert issubclass(ConfigError, KalcalError) and issubclass(ConfigError, ValueError)


def test_check_covariance_tolerates_rounding_but_not_real_asymmetry():
    base = np.array([[2.0, 0.5], [0.5, 1.0]])
    check_covariance("c", base + np.array([[0.0, 1e-13], [0.0, 0.0]]))
    with pytest.raises(ConfigError, match="^c: "):
        check_covariance("c", base + np.array([[0.0, 1e-3], [0.0, 0.0]]))
