"""Scenario settings: TOML files, ``section.key=value`` overrides, validation that names the key."""

from __future__ import annotations

import dataclasses

import pytest

from kalcal.errors import ConfigError
from kalcal.scenarios.accel_gps.settings import AccelGpsScenario
from kalcal.models.config import apply_settings, known_keys, load_toml, section_values
from kalcal.scenarios import build_scenario
from kalcal.models.settings import parse_assignments

# A valid, non-default value for every setting of the accel/GPS scenario.
NON_DEFAULT = {
    "scenario.duration": 12.0,
    "scenario.imu_rate": 100.0,
    "scenario.gps_rate": 4.0,
    "scenario.truth": "discrete",
    "scenario.integration": "trapezoid",
    "scenario.gps_fixes": "velocity",
    "truth.accel_amplitude": 5.0,
    "truth.accel_frequency": 0.2,
    "truth.accel_noise_std": 0.03,
    "truth.bias_std": 0.2,
    "truth.position0_mean": 1.5,
    "truth.position0_std": 5.0,
    "truth.velocity0_mean": 50.0,
    "truth.velocity0_std": 2.0,
    "truth.gps_position_std": 2.0,
    "truth.scale_std": 1e-3,
    "filter.scale_std": 2e-3,
    "truth.bias_walk_std": 1e-4,
    "truth.bias_correlation_time": 60.0,
    "filter.bias_walk_std": 2e-4,
    "filter.bias_correlation_time": 30.0,
    "truth.gps_velocity_std": 0.05,
    "filter.accel_noise_std": 0.025,
    "filter.bias_std": 0.15,
    "filter.position0_mean": -1.0,
    "filter.position0_std": 7.0,
    "filter.velocity0_mean": 99.0,
    "filter.velocity0_std": 1.5,
    "filter.gps_position_std": 1.25,
    "filter.gps_velocity_std": 0.045,
    "truth.gps_latency": 0.02,
    "truth.gps_outlier_rate": 0.01,
    "truth.gps_outlier_std": 30.0,
    "truth.gps_noise": "student-t",
    "truth.gps_noise_dof": 7,
    "filter.gps_latency": 0.015,
}
# The rate-free noise settings: each excludes its per-sample key of NON_DEFAULT, so they are tested apart.
DENSITY_KEYS = {
    "truth.accel_noise_density": 0.002,
    "truth.bias_walk_density": 1e-3,
    "filter.accel_noise_density": 0.0025,
    "filter.bias_walk_density": 2e-3,
}


def _value(scenario, key):
    section, name = key.split(".")
    return getattr(scenario.given_section(section), name)


def _toml_literal(value) -> str:
    return f'"{value}"' if isinstance(value, str) else repr(value)


def _write_toml(path, settings) -> None:
    sections: dict[str, list[str]] = {}
    for key, value in settings.items():
        section, name = key.split(".")
        sections.setdefault(section, []).append(f"{name} = {_toml_literal(value)}")
    path.write_text("".join(f"[{s}]\n" + "\n".join(lines) + "\n\n" for s, lines in sections.items()))


def test_non_default_table_covers_every_key():
    """If a setting is added, this table (and so the TOML test) must learn about it."""
    scenario = AccelGpsScenario()
    assert set(NON_DEFAULT) | set(DENSITY_KEYS) == set(known_keys(scenario))
    for key, value in {**NON_DEFAULT, **DENSITY_KEYS}.items():
        assert _value(scenario, key) != value, key


def test_toml_sets_every_key(tmp_path):
    path = tmp_path / "scenario.toml"
    _write_toml(path, NON_DEFAULT)
    scenario = build_scenario("accel-gps", config=path)
    for key, value in NON_DEFAULT.items():
        assert _value(scenario, key) == value, key
    assert scenario.scenario.steps_per_update == 25
    assert scenario.scenario.n_updates == 48


@pytest.mark.parametrize("key", sorted({**NON_DEFAULT, **DENSITY_KEYS}))
def test_each_key_from_a_command_line_string(key):
    value = {**NON_DEFAULT, **DENSITY_KEYS}[key]
    scenario = build_scenario("accel-gps", assignments=[f"{key}={value}"])
    assert _value(scenario, key) == value
    assert type(_value(scenario, key)) is type(value)


def test_toml_integers_are_accepted_for_float_settings(tmp_path):
    path = tmp_path / "ints.toml"
    path.write_text("[scenario]\nduration = 10\n[truth]\nvelocity0_mean = 90\n")
    scenario = build_scenario("accel-gps", config=path)
    assert scenario.scenario.duration == 10.0 and isinstance(scenario.scenario.duration, float)
    assert scenario.truth.velocity0_mean == 90.0


def test_set_overrides_toml_which_overrides_defaults(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text('[scenario]\nintegration = "euler"\n[truth]\nbias_std = 0.3\naccel_noise_std = 0.05\n')
    scenario = build_scenario(
        "accel-gps",
        config=path,
        assignments=["truth.bias_std=0.4"],
        defaults={"scenario.integration": "trapezoid", "truth.gps_position_std": 3.0},
    )
    assert scenario.truth.bias_std == 0.4  # --set beats TOML
    assert scenario.truth.accel_noise_std == 0.05  # TOML alone
    assert scenario.scenario.integration == "euler"  # TOML beats defaults
    assert scenario.truth.gps_position_std == 3.0  # defaults alone
    assert build_scenario("accel-gps", defaults={"scenario.integration": "trapezoid"}).scenario.integration == "trapezoid"


@pytest.mark.parametrize(
    "assignment, pattern",
    [
        ("foo.bar=1", r"^foo\.bar: expected a setting of .*, got an unknown section$"),  # unknown section
        ("truth.nope=1", r"^truth\.nope: expected a setting of \[truth\] .*, got an unknown key$"),  # unknown key
        ("truth.SECTION=x", r"^truth\.SECTION: .*got an unknown key$"),  # a class constant is not a setting
        ("truth=1", r"^truth: .*got an unknown key$"),  # no key
        ("truth.bias_std=abc", r"^truth\.bias_std: .*number.*'abc'"),
        ("truth.bias_std=nan", r"^truth\.bias_std: .*finite"),
        ("scenario.duration=inf", r"^scenario\.duration: .*finite"),
        ("scenario.truth=foo", r"^scenario\.truth: .*analytic.*discrete.*'foo'"),
        ("scenario.integration=rk4", r"^scenario\.integration: .*euler.*trapezoid.*'rk4'"),
        ("scenario.gps_rate=3", r"scenario\.gps_rate.*whole number"),
        ("scenario.imu_rate=201", r"imu_rate.*whole number"),
        ("scenario.duration=30.1", r"^scenario\.duration"),
        ("scenario.duration=-1", r"^scenario\.duration: .*positive"),
        ("truth.accel_noise_std=0", r"^truth\.accel_noise_std: .*positive"),
        ("truth.bias_std=-0.1", r"^truth\.bias_std"),
        ("filter.gps_position_std=-1", r"^filter\.gps_position_std: .*positive.*-1"),
        ("filter.bias_std=0", r"^filter\.bias_std: .*positive"),
    ],
)
def test_bad_settings_raise_config_error_naming_the_key(assignment, pattern):
    with pytest.raises(ConfigError, match=pattern):
        build_scenario("accel-gps", assignments=[assignment])


def test_apply_settings_direct():
    scenario = apply_settings(AccelGpsScenario(), {"truth.bias_std": 0.5, "filter.bias_std": "0.25"})
    assert scenario.truth.bias_std == 0.5 and scenario.filter.bias_std == 0.25
    with pytest.raises(ConfigError, match="truth.bias_std"):
        apply_settings(AccelGpsScenario(), {"truth.bias_std": True})
    with pytest.raises(ConfigError, match=r"^nosection\.x: .*unknown section"):
        apply_settings(AccelGpsScenario(), {"nosection.x": 1})


def test_apply_settings_returns_a_copy():
    original = AccelGpsScenario()
    changed = apply_settings(original, {"truth.bias_std": 0.5})
    assert original.truth.bias_std == 0.1 and changed.truth.bias_std == 0.5


def test_unknown_scenario_name():
    with pytest.raises(ConfigError, match="'nope'"):
        build_scenario("nope")


def test_parse_assignments():
    assert parse_assignments([" truth.bias_std = 0.2 ", "scenario.truth=discrete"]) == {
        "truth.bias_std": "0.2",
        "scenario.truth": "discrete",
    }
    with pytest.raises(ConfigError, match="truth.bias_std"):
        parse_assignments(["truth.bias_std"])
    with pytest.raises(ConfigError):
        parse_assignments(["=3"])


def test_toml_errors_name_the_file(tmp_path):
    missing = tmp_path / "missing.toml"
    with pytest.raises(ConfigError, match="missing.toml"):
        load_toml(missing)
    broken = tmp_path / "broken.toml"
    broken.write_text("[truth\nbias_std = \n")
    with pytest.raises(ConfigError, match="broken.toml.*TOML"):
        build_scenario("accel-gps", config=broken)
    flat = tmp_path / "flat.toml"
    flat.write_text("bias_std = 0.2\n")
    with pytest.raises(ConfigError, match="flat.toml.*bias_std"):
        build_scenario("accel-gps", config=flat)
    unknown = tmp_path / "unknown.toml"
    unknown.write_text("[trut]\nbias_std = 0.2\n")
    with pytest.raises(ConfigError, match=r"^.*unknown\.toml: trut\.bias_std: .*unknown section"):
        build_scenario("accel-gps", config=unknown)
    wrong_type = tmp_path / "wrong.toml"
    wrong_type.write_text('[truth]\nbias_std = "big"\n')
    with pytest.raises(ConfigError, match=r"truth\.bias_std.*'big'"):
        build_scenario("accel-gps", config=wrong_type)


def test_filter_settings_default_to_the_truth():
    scenario = AccelGpsScenario()
    assert scenario.filter_settings == scenario.truth
    assert all(getattr(scenario.filter, f.name) is None for f in dataclasses.fields(scenario.filter))


def test_filter_settings_can_be_set_apart_from_the_truth():
    scenario = build_scenario(
        "accel-gps", assignments=["filter.accel_noise_std=0.05", "truth.bias_std=0.2", "filter.gps_velocity_std=0.1"]
    )
    resolved = scenario.filter_settings
    assert resolved.accel_noise_std == 0.05 and scenario.truth.accel_noise_std == 0.02
    assert resolved.gps_velocity_std == 0.1 and scenario.truth.gps_velocity_std == 0.04
    assert resolved.bias_std == 0.2  # unset in [filter]: follows the truth
    assert resolved.accel_amplitude == scenario.truth.accel_amplitude
    # The filter's model uses the filter's values, the truth's model the truth's.
    assert scenario.filter_model().w[0, 0] == pytest.approx(0.05**2, rel=1e-15)
    assert scenario.truth_model().w[0, 0] == pytest.approx(0.02**2, rel=1e-15)
    assert scenario.filter_model().v[1, 1] == pytest.approx(0.1**2, rel=1e-15)
    assert scenario.filter_model().m0[2, 2] == pytest.approx(0.2**2, rel=1e-15)
    # "same" (or an empty value) unsets a filter setting again.
    again = apply_settings(scenario, {"filter.accel_noise_std": "same"})
    assert again.filter.accel_noise_std is None and again.filter_settings.accel_noise_std == 0.02


def test_section_values_round_trip():
    scenario = build_scenario("accel-gps", assignments=["truth.bias_std=0.2", "scenario.integration=trapezoid"])
    values = section_values(scenario)
    assert set(values) == {"scenario", "truth", "filter"}
    flat = {f"{s}.{k}": v for s, table in values.items() for k, v in table.items()}
    rebuilt = apply_settings(AccelGpsScenario(), flat)
    assert rebuilt == scenario
