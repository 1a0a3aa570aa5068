"""The scale/bias scenario: its settings, validation that names the key, and the parametrization."""

from __future__ import annotations

import numpy as np
import pytest

from kalcal.errors import ConfigError
from kalcal.models.config import known_keys
from kalcal.scenarios import SCENARIOS, build_scenario
from kalcal.scenarios.scale_bias.settings import ScaleBiasScenario
from kalcal.scenarios.scale_bias.theta import scale_bias_from_theta, scale_bias_jacobian, theta_from_scale_bias, theta_prior

# A valid, non-default value for every setting.
NON_DEFAULT = {
    "scenario.rate": 20.0,
    "scenario.duration": 12.5,
    "scenario.drift": "random-walk",
    "scenario.excitation": "reference",
    "scenario.unit": "K",
    "truth.scale_error": -0.03,
    "truth.scale_error_std": 0.01,
    "truth.bias": 0.2,
    "truth.bias_std": 0.3,
    "truth.reference_noise_std": 0.5,
    "truth.sensor_noise_std": 0.01,
    "truth.parameter_drift_std": 2e-3,
    "truth.signal_offset": 1.0,
    "truth.signal_amplitude": 3.0,
    "truth.signal_frequency": 0.5,
    "truth.signal_amplitude2": 0.0,
    "truth.signal_frequency2": 2.0,
    "filter.scale_error": 0.02,
    "filter.scale_error_std": 0.05,
    "filter.bias": -0.1,
    "filter.bias_std": 0.2,
    "filter.reference_noise_std": 0.3,
    "filter.sensor_noise_std": 0.003,
    "filter.parameter_drift_std": 1e-4,
    "filter.noise_model": "note",
    "filter.form": "note",
}


def _value(scenario, key):
    section, name = key.split(".")
    return getattr(getattr(scenario, section), name)


def test_registered_with_the_issues_keys():
    assert SCENARIOS["scale-bias"] is ScaleBiasScenario
    keys = set(known_keys(ScaleBiasScenario()))
    required = {
        "truth.scale_error",
        "truth.bias",
        "truth.reference_noise_std",
        "truth.sensor_noise_std",
        "filter.reference_noise_std",
        "filter.sensor_noise_std",
        "filter.parameter_drift_std",
        "scenario.rate",
        "scenario.duration",
    }
    assert required <= keys
    assert set(NON_DEFAULT) == keys
    for key, value in NON_DEFAULT.items():
        assert _value(ScaleBiasScenario(), key) != value, key


def test_every_key_from_toml_and_from_strings(tmp_path):
    lines: dict[str, list[str]] = {}
    for key, value in NON_DEFAULT.items():
        section, name = key.split(".")
        lines.setdefault(section, []).append(f"{name} = {value!r}".replace("'", '"'))
    path = tmp_path / "scale_bias.toml"
    path.write_text("".join(f"[{s}]\n" + "\n".join(v) + "\n" for s, v in lines.items()))
    from_toml = build_scenario("scale-bias", config=path)
    from_strings = build_scenario("scale-bias", assignments=[f"{k}={v}" for k, v in NON_DEFAULT.items()])
    for key, value in NON_DEFAULT.items():
        assert _value(from_toml, key) == value, key
        assert _value(from_strings, key) == value, key


def test_defaults_make_the_documented_study():
    scenario = ScaleBiasScenario()
    s, t = scenario.scenario, scenario.truth
    assert s.n_samples == 300
    times = s.sample_times()
    assert times[0] == pytest.approx(0.1) and times[-1] == pytest.approx(30.0)
    assert t.sensor_noise_std <= t.reference_noise_std / 50  # the note's sigma_nu << sigma_eta
    profile = scenario.profile(times)
    assert np.var(profile) == pytest.approx(2.125, rel=0.02)  # (2^2 + 0.5^2) / 2
    assert scenario.filter_settings.parameter_drift_std == 0.0  # Q = 0, as in the note
    np.testing.assert_array_equal(scenario.filter_process_noise(), np.zeros((2, 2)))
    np.testing.assert_array_equal(scenario.truth_process_noise(), np.zeros((2, 2)))
    assert scenario.state_units == ("1", "m/s^2")


def test_parametrization_round_trip_and_jacobian():
    a, b = np.array([0.01, -0.2, 0.5]), np.array([0.05, 1.0, -3.0])
    theta = theta_from_scale_bias(a, b)
    np.testing.assert_allclose(theta[:, 0], 1 / (1 - a), rtol=1e-15)
    np.testing.assert_allclose(theta[:, 1], b / (1 - a), rtol=1e-15)
    back_a, back_b = scale_bias_from_theta(theta)
    np.testing.assert_allclose(back_a, a, rtol=1e-13, atol=1e-16)
    np.testing.assert_allclose(back_b, b, rtol=1e-13)
    # d(a, b)/d(theta) by central differences
    step = 1e-6
    for i in range(3):
        numeric = np.empty((2, 2))
        for j in range(2):
            dt = np.zeros(2)
            dt[j] = step
            plus, minus = scale_bias_from_theta(theta[i] + dt), scale_bias_from_theta(theta[i] - dt)
            numeric[:, j] = (np.array(plus) - np.array(minus)) / (2 * step)
        np.testing.assert_allclose(scale_bias_jacobian(theta[i]), numeric, rtol=1e-8, atol=1e-10)


def test_theta_prior_is_the_first_order_image_of_the_prior_of_a_and_b():
    prior = theta_prior(0.1, 0.02, 0.3, 0.05)
    jac = np.linalg.inv(scale_bias_jacobian(prior.mean))  # d theta / d(a, b) at the mean
    np.testing.assert_allclose(prior.cov, jac @ np.diag([0.02**2, 0.05**2]) @ jac.T, rtol=1e-12)
    np.testing.assert_allclose(prior.mean, [1 / 0.9, 0.3 / 0.9], rtol=1e-15)


def test_filter_settings_fall_back_to_the_truth():
    scenario = build_scenario("scale-bias", assignments=["truth.bias=0.4", "filter.sensor_noise_std=0.01"])
    f = scenario.filter_settings
    assert f.bias == 0.4 and f.sensor_noise_std == 0.01 and f.reference_noise_std == 0.2
    # parameter_drift_std "same": the truth's drift when it drifts, else none.
    same = build_scenario("scale-bias", assignments=["filter.parameter_drift_std=same"])
    assert same.filter_settings.parameter_drift_std == 0.0
    drifting = build_scenario("scale-bias", assignments=["filter.parameter_drift_std=same", "scenario.drift=random-walk"])
    assert drifting.filter_settings.parameter_drift_std == drifting.truth.parameter_drift_std == 1e-3
    np.testing.assert_allclose(drifting.truth_process_noise(), 1e-6 * np.eye(2))
    np.testing.assert_allclose(drifting.filter_process_noise(), 1e-6 * np.eye(2))


def test_measurement_noise_exact_and_note():
    exact = build_scenario("scale-bias", assignments=["truth.scale_error=0.2", "truth.sensor_noise_std=0.1"])
    note = build_scenario("scale-bias", assignments=["truth.scale_error=0.2", "truth.sensor_noise_std=0.1", "filter.noise_model=note"])
    theta1 = 1 / 0.8
    assert exact.filter_noise_variance() == pytest.approx(0.2**2 + theta1**2 * 0.1**2, rel=1e-14)
    assert note.filter_noise_variance() == pytest.approx(0.2**2 + 0.1**2, rel=1e-14)


@pytest.mark.parametrize(
    ("assignment", "key"),
    [
        ("truth.scale_error=1", "truth.scale_error"),
        ("filter.scale_error=1.5", "filter.scale_error"),
        ("truth.reference_noise_std=0", "truth.reference_noise_std"),
        ("truth.sensor_noise_std=-0.1", "truth.sensor_noise_std"),
        ("truth.bias_std=-1", "truth.bias_std"),
        ("truth.parameter_drift_std=-1e-3", "truth.parameter_drift_std"),
        ("filter.scale_error_std=0", "filter.scale_error_std"),
        ("filter.parameter_drift_std=-1", "filter.parameter_drift_std"),
        ("scenario.rate=0", "scenario.rate"),
        ("scenario.duration=0.05", "scenario.duration"),
        ("scenario.drift=sometimes", "scenario.drift"),
        ("filter.noise_model=approximate", "filter.noise_model"),
        ("filter.form=square-root", "filter.form"),
        ("scenario.unit=", "scenario.unit"),
        ("truth.scale_error_std=0", "filter.scale_error_std"),
    ],
)
def test_bad_settings_name_the_key(assignment, key):
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        build_scenario("scale-bias", assignments=[assignment])


def test_a_known_parameter_in_the_truth_needs_the_filters_own_prior():
    scenario = build_scenario("scale-bias", assignments=["truth.bias_std=0", "filter.bias_std=0.1"])
    # b known: theta2 = b theta1 moves only with theta1, so the truth's prior has rank one.
    eigenvalues = np.linalg.eigvalsh(scenario.truth_prior().cov)
    assert eigenvalues[0] < 1e-15 * eigenvalues[1]
    assert np.linalg.eigvalsh(scenario.filter_prior().cov)[0] > 0
