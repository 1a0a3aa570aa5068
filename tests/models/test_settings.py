"""The settings layer: the error wording, each converter and rule, and file versus --set as the source."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from kalcal.errors import ConfigError, KalcalError
from kalcal.models import settings as st
from kalcal.scenarios.model_file.model import parse_model
from kalcal.scenarios import build_scenario
from kalcal.models.settings import SettingError


def _message(call, *args, **kwargs) -> str:
    with pytest.raises(SettingError) as info:
        call(*args, **kwargs)
    message = str(info.value)
    assert "\n" not in message
    return message


# --- the wording -------------------------------------------------------------------------------------


def test_the_wording_with_and_without_a_file_and_a_key():
    assert str(SettingError("truth.bias_std", "a number", "'abc'")) == "truth.bias_std: expected a number, got 'abc'"
    assert str(SettingError("w", "a matrix", "0.5", "m.toml")) == "m.toml: w: expected a matrix, got 0.5"
    assert str(SettingError(None, "valid TOML", "a syntax error", "m.toml")) == "m.toml: expected valid TOML, got a syntax error"
    assert str(SettingError(None, "x", "y")) == "expected x, got y"


def test_a_setting_error_is_a_config_error_and_keeps_its_parts():
    error = SettingError("w", "a matrix", "0.5", "m.toml")
    assert isinstance(error, ConfigError) and isinstance(error, KalcalError) and isinstance(error, ValueError)
    assert (error.key, error.expected, error.got, error.source) == ("w", "a matrix", "0.5", "m.toml")
    again = pickle.loads(pickle.dumps(error))
    assert type(again) is SettingError and str(again) == str(error) and again.key == "w"


def test_an_error_can_be_relocated():
    error = SettingError("w", "shape (1, 1)", "(1, 2)")
    assert str(error.located(source="m.toml")) == "m.toml: w: expected shape (1, 1), got (1, 2)"
    assert str(error.located(key="truth.w", got="(1, 2) (why)")) == "truth.w: expected shape (1, 1), got (1, 2) (why)"
    assert str(error.located(source="m.toml").from_assignment("filter.w")) == "filter.w: expected shape (1, 1), got (1, 2)"


def test_show_writes_one_line():
    assert st.show(np.array([[1.0, 0.5], [0.0, 2.0]])) == "[[1.0, 0.5], [0.0, 2.0]]"
    assert st.show(np.float64(0.25)) == "0.25" and st.show(np.int64(3)) == "3"
    assert st.show("abc") == "'abc'" and st.show(True) == "True"
    long = st.show(np.zeros((30, 30)))
    assert len(long) == 120 and long.endswith("...") and "\n" not in long
    assert [st.type_name(v) for v in (True, "a", {}, [], 3)] == ["a boolean", "a string", "a table", "an array", "int"]


# --- reading -----------------------------------------------------------------------------------------


def test_parse_assignments():
    assert st.parse_assignments([" a.b = 1 ", "c.d=x=y"]) == {"a.b": "1", "c.d": "x=y"}
    assert _message(st.parse_assignments, ["a.b"]) == "--set: expected section.key=value, got 'a.b'"
    assert _message(st.parse_assignments, ["=3"]) == "--set: expected section.key=value, got '=3'"


def test_toml_values_from_the_command_line():
    assert st.toml_value("filter.w", "[[0.01]]") == [[0.01]] and st.toml_value("model.updates", "60") == 60
    assert st.toml_value("model.name", "plant-b", bare_string=True) == "plant-b"
    expected = "filter.w: expected a TOML value (e.g. [[0.01]], 60, 0.1), got '[[0.1'"
    assert _message(st.toml_value, "filter.w", "[[0.1") == expected


def test_reading_a_toml_file(tmp_path):
    good = tmp_path / "good.toml"
    good.write_text("[truth]\nbias_std = 0.2\n")
    assert st.read_toml(good, "config file") == {"truth": {"bias_std": 0.2}}
    missing = tmp_path / "none.toml"
    assert _message(st.read_toml, missing, "config file") == f"{missing}: expected a readable config file, got no such file"
    folder = _message(st.read_toml, tmp_path, "model file")
    assert folder.startswith(f"{tmp_path}: expected a readable model file, got an unreadable file (")
    binary = tmp_path / "binary.toml"
    binary.write_bytes(b"\xff\xfe\x00")
    assert _message(st.read_toml, binary, "model file").startswith(f"{binary}: expected a readable model file, got an unreadable")
    assert _message(st.parse_toml, "a = [1,", "x.toml").startswith("x.toml: expected valid TOML, got a syntax error (")


def test_unknown_and_missing_keys():
    expected = "truth.q: expected a setting of [truth] (a, b), got an unknown key"
    assert str(st.unknown("truth.q", "a setting of [truth] (a, b)")) == expected
    assert str(st.unknown("foo.q", "a setting of [truth]", "section")).endswith("got an unknown section")
    assert str(st.missing("phi", "a matrix")) == "phi: expected a matrix, got nothing (a required key)"


# --- converters --------------------------------------------------------------------------------------


def test_to_float():
    assert st.to_float("k", "0.5") == 0.5 and st.to_float("k", 2) == 2.0 and isinstance(st.to_float("k", 2), float)
    assert _message(st.to_float, "k", "abc") == "k: expected a number, got 'abc'"
    assert _message(st.to_float, "k", True) == "k: expected a number, got True"
    assert _message(st.to_float, "k", None) == "k: expected a number, got None"
    assert _message(st.to_float, "k", "nan") == "k: expected a finite number, got 'nan'"
    assert _message(st.to_float, "k", float("-inf")) == "k: expected a finite number, got -inf"


def test_to_int():
    assert st.to_int("k", "3") == 3 and st.to_int("k", 3.0) == 3 and type(st.to_int("k", "3.0")) is int
    assert _message(st.to_int, "k", "2.5") == "k: expected a whole number, got '2.5'"
    assert _message(st.to_int, "k", "x") == "k: expected a number, got 'x'"


@pytest.mark.parametrize(
    "text, value",
    [("true", True), ("YES", True), ("1", True), ("False", False), ("no", False), ("0", False), (True, True)],
)
def test_to_bool(text, value):
    assert st.to_bool("k", text) is value


def test_to_bool_refuses_other_words():
    assert _message(st.to_bool, "k", "maybe") == "k: expected true or false, got 'maybe'"


def test_to_choice():
    assert st.to_choice("k", "euler", ("euler", "trapezoid")) == "euler"
    assert _message(st.to_choice, "k", "rk4", ("euler", "trapezoid")) == "k: expected one of euler, trapezoid, got 'rk4'"


def test_strict_scalars_of_a_model_file():
    assert st.to_positive_integer("k", 3) == 3
    for bad, shown in ((0, "0"), (2.5, "2.5"), (True, "True"), ("4", "'4'")):
        assert _message(st.to_positive_integer, "k", bad) == f"k: expected a positive integer, got {shown}"
    assert st.to_positive_number("k", 1) == 1.0 and isinstance(st.to_positive_number("k", 1), float)
    for bad, shown in ((0.0, "0.0"), (-1, "-1"), (float("inf"), "inf"), ("1", "'1'"), (False, "False")):
        assert _message(st.to_positive_number, "k", bad, "a positive number of seconds") == (
            f"k: expected a positive number of seconds, got {shown}"
        )
    assert st.to_string("k", "a") == "a"
    assert _message(st.to_string, "k", 3) == "k: expected a string, got 3"


def test_to_labels():
    assert st.to_labels("k", ["a", "b"]) == ("a", "b") and st.to_labels("k", [], 0) == ()
    assert _message(st.to_labels, "k", "ab") == "k: expected an array of strings, got 'ab'"
    assert _message(st.to_labels, "k", ["a", 1]) == "k: expected an array of strings, got ['a', 1]"
    assert _message(st.to_labels, "k", ["a"], 2, "state") == "k: expected 2 entries (one per state), got 1: ['a']"
    assert _message(st.to_labels, "k", ["a"], 2) == "k: expected 2 entries, got 1: ['a']"


def test_to_matrix():
    matrix = st.to_matrix("k", [[1, 0.5], [0, 2]])
    assert matrix.dtype == float and matrix.shape == (2, 2)
    example = "[[1.0, 0.0], [0.0, 1.0]]"
    assert _message(st.to_matrix, "k", [1.0]) == f"k: expected a matrix, an array of rows such as {example}, got [1.0]"
    assert _message(st.to_matrix, "k", []) == f"k: expected a non-empty matrix such as {example}, got []"
    assert _message(st.to_matrix, "k", [[1.0], [False]]) == "k: expected numbers, got False (a boolean) in row 2"
    assert _message(st.to_matrix, "k", [[1.0], [1.0, 2.0]]) == "k: expected rows of one length, got rows of lengths 1, 2"


def test_to_vector():
    assert st.to_vector("k", [1, 2.5]).tolist() == [1.0, 2.5]
    assert _message(st.to_vector, "k", 1.0) == "k: expected an array of numbers such as [0.0, 1.0], got 1.0"
    assert _message(st.to_vector, "k", [1.0, [2.0]]) == "k: expected numbers, got [2.0] (an array)"


# --- range rules -------------------------------------------------------------------------------------


def test_positive_and_nonnegative():
    st.require_positive("truth", a=1.0, b=None)
    st.require_nonnegative("truth", a=0.0, b=None)
    assert _message(st.require_positive, "truth", a=1.0, b=0.0) == "truth.b: expected a positive number, got 0.0"
    assert _message(st.require_positive, "truth", a=float("nan")) == "truth.a: expected a positive number, got nan"
    assert _message(st.require_nonnegative, "filter", c=-0.5) == "filter.c: expected zero or a positive number, got -0.5"


def test_below_whole_and_shape():
    st.require_below("k", 0.5, 1.0)
    st.require_below("k", None, 1.0)
    assert _message(st.require_below, "k", 1.0, 1.0, "a gain") == "k: expected a number less than 1 (a gain), got 1.0"
    st.require_whole("k", 40.0 * (1 + 1e-12), "whole", "x")
    for ratio in (0.4, 2.5):
        assert _message(st.require_whole, "k", ratio, "a whole number", "it") == "k: expected a whole number, got it"
    st.require_shape("k", np.zeros((2, 3)), (2, 3))
    expected = "k: expected shape (2, 2) to match phi, got (2, 3)"
    assert _message(st.require_shape, "k", np.zeros((2, 3)), (2, 2), "to match phi") == expected


# --- the source: a file or a --set assignment -----------------------------------------------------------


def test_a_config_files_value_names_the_file_and_an_assignment_its_key(tmp_path):
    config = tmp_path / "bench.toml"
    config.write_text("[truth]\nbias_std = -0.1\naccel_noise_std = 0.05\n")
    expected = "truth.bias_std: expected zero or a positive number, got -0.1"
    assert _message(build_scenario, "accel-gps", config) == f"{config}: {expected}"
    # the same key set again by --set: the bad value is the assignment's, and the file is not named
    assert _message(build_scenario, "accel-gps", config, ["truth.bias_std=-0.2"]) == expected.replace("-0.1", "-0.2")
    assert build_scenario("accel-gps", config, ["truth.bias_std=0.2"]).truth.bias_std == 0.2


def test_a_config_files_conversion_and_cross_field_errors_name_the_file(tmp_path):
    config = tmp_path / "bench.toml"
    config.write_text('[scenario]\ngps_rate = 3.0\n[filter]\nbias_std = "big"\n')
    assert _message(build_scenario, "accel-gps", config) == f"{config}: filter.bias_std: expected a number, got 'big'"
    message = _message(build_scenario, "accel-gps", config, ["filter.bias_std=0.2"])
    assert message.startswith(f"{config}: scenario.gps_rate: expected a rate that makes imu_rate / gps_rate a whole")
    assert message.endswith("got 3.0 (imu_rate / gps_rate = 200 / 3 = 66.6667)")
    config.write_text("[scenario]\nduration = 10.1\n")
    assert _message(build_scenario, "accel-gps", config).startswith(f"{config}: scenario.duration: ")
    assert _message(build_scenario, "accel-gps", None, ["scenario.duration=10.1"]).startswith("scenario.duration: ")
    # an error names the source of its own key: here gps_rate, a default, against the file's imu_rate
    config.write_text("[scenario]\nimu_rate = 201.0\n")
    message = _message(build_scenario, "accel-gps", config)
    assert message.startswith("scenario.gps_rate: ") and "201 / 5" in message


def test_a_model_files_value_names_the_file_and_an_assignment_its_key():
    text = "steps_per_update = 1\nupdates = 2\nphi = [[1.0]]\ngamma = [[1.0]]\nh = [[1.0]]\n"
    text += "w = [[-1.0]]\nv = [[1.0]]\nx0 = [0.0]\nm0 = [[1.0]]\n"
    assert _message(parse_model, text, "m.toml") == (
        "m.toml: w: expected a positive semi-definite covariance, got [[-1.0]] (eigenvalue -1)"
    )
    fixed = text.replace("w = [[-1.0]]", "w = [[1.0]]")
    assert _message(parse_model, fixed, "m.toml", ["filter.w=[[-2.0]]"]) == (
        "filter.w: expected a positive semi-definite covariance, got [[-2.0]] (eigenvalue -2)"
    )
    assert _message(parse_model, fixed, "m.toml", ["truth.m0=[[1.0, 0.0]]"]) == "truth.m0: expected shape (1, 1), got (1, 2)"
    assert _message(parse_model, fixed, "m.toml", ["model.name=7"]) == "model.name: expected a string, got 7"
