"""Model files: parsing, --set overrides, the rebuild from summary settings, and every validation error."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from kalcal.errors import ConfigError
from kalcal.io.results import to_jsonable
from kalcal.models.config import section_values
from kalcal.scenarios.model_file.model import MODEL_KEYS, CustomModelScenario, is_custom_settings, load_model_file, parse_model

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
SOURCE = "my-model.toml"

#: A valid 3-state, 2-measurement model written key by key, so that a test can replace one line.
BASE = {
    "steps_per_update": "5",
    "updates": "4",
    "phi": "[[1.0, 0.1, 0.0], [0.0, 1.0, 0.1], [0.0, 0.0, 1.0]]",
    "gamma": "[[0.0], [0.0], [0.1]]",
    "h": "[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]",
    "w": "[[0.5]]",
    "v": "[[1.0, 0.0], [0.0, 0.25]]",
    "x0": "[0.0, 1.0, 0.0]",
    "m0": "[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]",
}


def _text(table: dict[str, str] | None = None, **changes: str | None) -> str:
    """The BASE file with keys replaced (None removes one) and a [truth] table."""
    values = {**BASE, **changes}
    lines = [f"{key} = {value}" for key, value in values.items() if value is not None]
    if table is not None:
        lines += ["[truth]"] + [f"{key} = {value}" for key, value in table.items()]
    return "\n".join(lines) + "\n"


def _error(text: str, assignments=()) -> str:
    with pytest.raises(ConfigError) as info:
        parse_model(text, SOURCE, assignments)
    message = str(info.value)
    assert "\n" not in message
    return message


def _same_model(a, b) -> None:
    for key in MODEL_KEYS:
        np.testing.assert_array_equal(getattr(a, key), getattr(b, key), err_msg=key)
    assert (a.steps_per_update, a.sample_period) == (b.steps_per_update, b.sample_period)


def test_the_example_file_parses():
    scenario = load_model_file(EXAMPLES / "constant_velocity.toml")
    f = scenario.filter
    assert scenario.model.name == "constant-velocity" and scenario.model.updates == 30
    assert (f.state_dim, f.measurement_dim, f.steps_per_update) == (2, 1, 10)
    assert f.sample_period == 0.1 and f.update_period == pytest.approx(1.0, rel=1e-15)
    np.testing.assert_array_equal(f.phi, [[1.0, 0.1], [0.0, 1.0]])
    np.testing.assert_array_equal(f.gamma, [[0.005], [0.1]])
    assert scenario.model.state_names == ("position", "velocity") and scenario.model.state_units == ("m", "m/s")
    assert scenario.model.measurement_names == ("position",)
    assert scenario.differing() == ()
    _same_model(scenario.truth, f)
    np.testing.assert_allclose(scenario.update_times, np.arange(1, 31), rtol=1e-15)


def test_the_mistuned_example_differs_in_the_process_noise_only():
    scenario = load_model_file(EXAMPLES / "constant_velocity_mistuned.toml")
    assert scenario.differing() == ("w",)
    assert scenario.filter.w[0, 0] == 0.0025 and scenario.truth.w[0, 0] == 0.04


def test_defaults_name_timing_and_labels():
    scenario = parse_model(_text(), "dir/plant.toml")
    assert scenario.model.name == "plant" and scenario.model.file == "dir/plant.toml"
    assert scenario.filter.sample_period == 1.0
    assert scenario.model.state_names == ("x1", "x2", "x3") and scenario.model.state_units == ("", "", "")
    assert scenario.model.measurement_names == ("z1", "z2") and scenario.model.measurement_units == ("", "")
    np.testing.assert_array_equal(scenario.update_times, [5.0, 10.0, 15.0, 20.0])


def test_a_truth_table_overrides_only_what_it_sets():
    scenario = parse_model(_text(table={"w": "[[2.0]]", "x0": "[1.0, 1.0, 0.0]"}), SOURCE)
    assert scenario.differing() == ("w", "x0")
    np.testing.assert_array_equal(scenario.truth.phi, scenario.filter.phi)
    assert scenario.truth.w[0, 0] == 2.0 and scenario.filter.w[0, 0] == 0.5


def test_settings_round_trip_through_json():
    scenario = parse_model(_text(table={"v": "[[2.0, 0.5], [0.5, 1.0]]"}, sample_period="0.01"), SOURCE)
    settings = json.loads(json.dumps(to_jsonable(section_values(scenario))))
    # a file without inputs, data-named rows or diffuse states keeps the section of a time-invariant model
    assert is_custom_settings(settings) and set(settings["filter"]) == {*MODEL_KEYS, "steps_per_update", "sample_period"}
    rebuilt = CustomModelScenario.from_settings(settings)
    assert rebuilt.model == scenario.model
    _same_model(rebuilt.filter, scenario.filter)
    _same_model(rebuilt.truth, scenario.truth)
    assert not is_custom_settings({"scenario": {}, "truth": {}, "filter": {}})
    with pytest.raises(ConfigError, match="custom model settings"):
        CustomModelScenario.from_settings({**settings, "model": {"name": "x"}})


def test_set_overrides_the_filter_the_truth_and_the_model():
    text = _text()
    scenario = parse_model(text, SOURCE, ["filter.w=[[0.1]]", "truth.v=[[2.0, 0.0], [0.0, 1.0]]", "model.updates=7"])
    assert scenario.filter.w[0, 0] == 0.1
    assert scenario.truth.w[0, 0] == 0.5  # filter.KEY retunes the filter alone: the truth keeps the file's w
    assert scenario.truth.v[0, 0] == 2.0 and scenario.filter.v[0, 0] == 1.0
    assert scenario.model.updates == 7 and scenario.differing() == ("w", "v")
    named = parse_model(text, SOURCE, ["model.name=plant-b", "filter.sample_period=0.5", "filter.steps_per_update=2"])
    assert named.model.name == "plant-b" and named.filter.update_period == 1.0 and named.truth.update_period == 1.0
    # a [truth] value wins over the file's when the filter is retuned
    both = parse_model(_text(table={"w": "[[3.0]]"}), SOURCE, ["filter.w=[[0.1]]"])
    assert both.truth.w[0, 0] == 3.0 and both.filter.w[0, 0] == 0.1


@pytest.mark.parametrize(
    "assignment, fragment",
    [
        ("filter.q=1", "filter.q: expected a model file's setting (model.{name,"),
        ("truth.steps_per_update=2", "truth.steps_per_update: expected a model file's setting"),
        ("scenario.duration=4", "scenario.duration: expected a model file's setting"),
        ("filter.w=[[0.1", "filter.w: expected a TOML value (e.g. [[0.01]], 60, 0.1), got '[[0.1'"),
        ("filter.w", "--set: expected section.key=value, got 'filter.w'"),
    ],
)
def test_bad_set_is_one_line(assignment, fragment):
    assert fragment in _error(_text(), [assignment])


def test_an_unknown_set_key_lists_the_known_ones():
    known = (
        "model.{name, updates, state_names, state_units, measurement_names, measurement_units}; "
        "filter.{phi, gamma, h, w, v, x0, m0, b, diffuse, steps_per_update, sample_period}; "
        "truth.{phi, gamma, h, w, v, x0, m0, b}; data.{time, measurements, inputs, stds, step_tolerance}, "
        "or one number of a matrix: KEY.I, KEY.I.J"
    )
    assert _error(_text(), ["filter.q=1"]) == f"filter.q: expected a model file's setting ({known}), got an unknown setting"


def test_set_errors_name_the_override_and_file_errors_the_file():
    message = _error(_text(), ["filter.w=[[0.1, 0.0]]"])
    assert message == "filter.w: expected shape (1, 1), got (1, 2)"
    assert _error(_text(), ["truth.v=[[-1.0]]"]) == "truth.v: expected shape (2, 2), got (1, 1)"
    assert _error(_text(), ["model.updates=0"]) == "model.updates: expected a positive integer, got 0"
    # an override that leaves a value of the file unfit: the file's value is named, with the file
    assert _error(_text(), ["filter.gamma=[[0.0, 0.0], [0.0, 0.0], [0.1, 0.0]]"]) == (
        f"{SOURCE}: w: expected shape (2, 2), got (1, 1)"
    )


SHAPES = [
    ({"phi": "[[1.0, 0.1, 0.0], [0.0, 1.0, 0.1]]"}, "phi: expected a square matrix, got shape (2, 3)"),
    ({"gamma": "[[0.0], [0.1]]"}, "gamma: expected 3 rows to match phi, got shape (2, 1)"),
    ({"h": "[[1.0, 0.0], [0.0, 1.0]]"}, "h: expected 3 columns to match phi, got shape (2, 2)"),
    ({"w": "[[0.5, 0.0], [0.0, 0.5]]"}, "w: expected shape (1, 1), got (2, 2)"),
    ({"v": "[[1.0]]"}, "v: expected shape (2, 2), got (1, 1)"),
    ({"x0": "[0.0, 1.0]"}, "x0: expected 3 entries to match phi, got 2"),
    ({"m0": "[[1.0, 0.0], [0.0, 1.0]]"}, "m0: expected shape (3, 3), got (2, 2)"),
]


@pytest.mark.parametrize("changes, expected", SHAPES, ids=[next(iter(c)) for c, _ in SHAPES])
def test_a_matrix_of_the_wrong_shape_is_named(changes, expected):
    assert _error(_text(**changes)) == f"{SOURCE}: {expected}"


@pytest.mark.parametrize("changes, expected", SHAPES, ids=[next(iter(c)) for c, _ in SHAPES])
def test_a_truth_matrix_of_the_wrong_shape_is_named(changes, expected):
    assert _error(_text(table=changes)) == f"{SOURCE}: truth.{expected}"


def test_an_inherited_truth_matrix_that_no_longer_fits_says_so():
    message = _error(_text(table={"gamma": "[[0.0, 0.0], [0.0, 0.0], [0.1, 0.0]]"}))
    assert message == f"{SOURCE}: truth.w: expected shape (2, 2), got (1, 1) ([truth] does not set w, so it is the filter's)"


def test_the_truth_must_have_the_filters_dimensions():
    truth = {
        "phi": "[[1.0, 0.1], [0.0, 1.0]]", "gamma": "[[0.0], [0.1]]", "h": "[[1.0, 0.0], [0.0, 1.0]]",
        "x0": "[0.0, 0.0]", "m0": "[[1.0, 0.0], [0.0, 1.0]]",
    }  # fmt: skip
    assert _error(_text(table=truth)) == f"{SOURCE}: truth.phi: expected shape (3, 3) like the filter's phi, got (2, 2)"


ASYMMETRIC = {
    # a 1 x 1 w is always symmetric: two noise inputs
    "w": {"gamma": "[[0.0, 0.0], [0.0, 0.0], [0.1, 0.0]]", "w": "[[0.5, 0.1], [0.0, 0.5]]"},
    "v": {"v": "[[1.0, 0.1], [0.0, 0.25]]"},
    "m0": {"m0": "[[1.0, 0.2, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]"},
}


@pytest.mark.parametrize("key", list(ASYMMETRIC))
@pytest.mark.parametrize("section", ["filter", "truth"])
def test_an_asymmetric_covariance_is_named(key, section):
    changes = ASYMMETRIC[key]
    text = _text(**changes) if section == "filter" else _text(table=changes)
    prefix = "" if section == "filter" else "truth."
    matrix = list(changes.values())[-1].replace('"', "")
    assert _error(text) == f"{SOURCE}: {prefix}{key}: expected a symmetric covariance, got {matrix}"


@pytest.mark.parametrize(
    "changes, expected",
    [
        ({"w": "[[-0.5]]"}, "w: expected a positive semi-definite covariance, got [[-0.5]] (eigenvalue -0.5)"),
        (
            {"m0": "[[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]]"},
            "m0: expected a positive semi-definite covariance, got [[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]] (eigenvalue -1)",
        ),
        ({"v": "[[1.0, 0.0], [0.0, -1.0]]"}, "v: expected a positive semi-definite covariance, got [[1.0, 0.0], [0.0, -1.0]] (eigenvalue -1)"),
        ({"v": "[[1.0, 0.0], [0.0, 0.0]]"}, "v: expected a positive definite measurement-noise covariance, got [[1.0, 0.0], [0.0, 0.0]]"),
    ],
)
def test_a_covariance_that_is_not_psd_is_named(changes, expected):
    assert _error(_text(**changes)) == f"{SOURCE}: {expected}"
    assert _error(_text(table=changes)) == f"{SOURCE}: truth.{expected}"


@pytest.mark.parametrize("key", list(BASE))
def test_a_missing_key_is_named(key):
    what = {"steps_per_update": "a positive integer", "updates": "a positive integer", "x0": "an array of numbers"}
    assert _error(_text(**{key: None})) == f"{SOURCE}: {key}: expected {what.get(key, 'a matrix')}, got nothing (a required key)"


def test_unknown_keys_are_named():
    assert _error(_text(q="[[1.0]]")).startswith(f"{SOURCE}: q: expected a model file's key (name, sample_period,")
    assert _error(_text(q="[[1.0]]")).endswith("a [truth] or a [data] table), got an unknown key")
    assert _error(_text(table={"updates": "3"})) == (
        f"{SOURCE}: truth.updates: expected a matrix of [truth] (phi, gamma, h, w, v, x0, m0, b), got an unknown key"
    )


@pytest.mark.parametrize(
    "changes, expected",
    [
        ({"h": '"identity"'}, "h: expected a matrix, an array of rows such as [[1.0, 0.0], [0.0, 1.0]], got 'identity'"),
        ({"w": "0.5"}, "w: expected a matrix, an array of rows such as [[1.0, 0.0], [0.0, 1.0]], got 0.5"),
        ({"w": "[0.5]"}, "w: expected a matrix, an array of rows such as [[1.0, 0.0], [0.0, 1.0]], got [0.5]"),
        ({"w": "[[]]"}, "w: expected a non-empty matrix such as [[1.0, 0.0], [0.0, 1.0]], got [[]]"),
        ({"v": '[[1.0, "a"], [0.0, 1.0]]'}, "v: expected numbers, got 'a' (a string) in row 1"),
        ({"phi": "[[1.0, 0.1, 0.0], [0.0, true, 0.1], [0.0, 0.0, 1.0]]"}, "phi: expected numbers, got True (a boolean) in row 2"),
        ({"m0": "[[1.0, 0.0, 0.0], [0.0, 1.0], [0.0, 0.0, 1.0]]"}, "m0: expected rows of one length, got rows of lengths 2, 3"),
        ({"gamma": "[[0.0], [0.0], [nan]]"}, "gamma: expected finite numbers, got [[0.0], [0.0], [nan]]"),
        ({"x0": "[0.0, 1.0, 'a']"}, "x0: expected numbers, got 'a' (a string)"),
        ({"x0": "0.0"}, "x0: expected an array of numbers such as [0.0, 1.0], got 0.0"),
        ({"steps_per_update": "2.5"}, "steps_per_update: expected a positive integer, got 2.5"),
        ({"steps_per_update": "0"}, "steps_per_update: expected a positive integer, got 0"),
        ({"updates": "true"}, "updates: expected a positive integer, got True"),
        ({"updates": '"4"'}, "updates: expected a positive integer, got '4'"),
        ({"sample_period": "-0.1"}, "sample_period: expected a positive number of seconds, got -0.1"),
        ({"sample_period": '"fast"'}, "sample_period: expected a positive number of seconds, got 'fast'"),
        ({"name": "3"}, "name: expected a string, got 3"),
        ({"name": '"accel-gps"'}, "name: expected a name other than a built-in scenario's (accel-gps, scale-bias, imu-3axis), got 'accel-gps'"),
        ({"state_names": '["a", "b"]'}, "state_names: expected 3 entries (one per state), got 2: ['a', 'b']"),
        ({"measurement_units": "[1, 2]"}, "measurement_units: expected an array of strings, got [1, 2]"),
        ({"truth": "3"}, "truth: expected a [truth] table of matrices, got int"),
    ],
)
def test_wrong_types_are_named(changes, expected):
    assert _error(_text(**changes)) == f"{SOURCE}: {expected}"


def test_a_non_numeric_truth_matrix_is_named():
    assert _error(_text(table={"w": '[["big"]]'})) == f"{SOURCE}: truth.w: expected numbers, got 'big' (a string) in row 1"


def test_invalid_toml_and_missing_files_are_one_line(tmp_path):
    assert _error("phi = [[1.0, ").startswith(f"{SOURCE}: expected valid TOML, got a syntax error (")
    with pytest.raises(ConfigError, match=r"nothing\.toml: expected a readable model file, got no such file$"):
        load_model_file(tmp_path / "nothing.toml")
    with pytest.raises(ConfigError, match=r"^--config: expected no config file with a model file .*, got '.*x\.toml'$"):
        load_model_file(EXAMPLES / "constant_velocity.toml", config=tmp_path / "x.toml")
