"""A model file's truth of its own dimension ([truth] map): parsing, --set, the summary rebuild, each error."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from kalcal.core.model import LinearGaussianModel
from kalcal.errors import ConfigError
from kalcal.io.results import to_jsonable
from kalcal.models.config import section_values
from kalcal.scenarios.model_file.model import MODEL_KEYS, CustomModelScenario, load_model_file, parse_model
from kalcal.scenarios.model_file.truth import MappedTruthModel

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
SOURCE = "reduced.toml"

#: A 1-state random-walk filter (top level) against a 2-state truth: the state and a Gauss-Markov fix error.
FILTER = {
    "steps_per_update": "2",
    "updates": "5",
    "phi": "[[1.0]]",
    "gamma": "[[1.0]]",
    "w": "[[0.01]]",
    "h": "[[1.0]]",
    "v": "[[1.0]]",
    "x0": "[0.0]",
    "m0": "[[4.0]]",
}
TRUTH = {
    "map": "[[1.0, 0.0]]",
    "phi": "[[1.0, 0.0], [0.0, 0.9]]",
    "gamma": "[[1.0, 0.0], [0.0, 1.0]]",
    "w": "[[0.01, 0.0], [0.0, 0.19]]",
    "h": "[[1.0, 1.0]]",
    "v": "[[1.0]]",
    "x0": "[0.0, 0.0]",
    "m0": "[[4.0, 0.0], [0.0, 1.0]]",
}


def _text(**truth_changes: str | None) -> str:
    """FILTER with a [truth] table of TRUTH with keys replaced (None removes one)."""
    table = {**TRUTH, **truth_changes}
    lines = [f"{key} = {value}" for key, value in FILTER.items()]
    lines += ["[truth]"] + [f"{key} = {value}" for key, value in table.items() if value is not None]
    return "\n".join(lines) + "\n"


def _error(text: str, assignments=()) -> str:
    with pytest.raises(ConfigError) as info:
        parse_model(text, SOURCE, assignments)
    message = str(info.value)
    assert "\n" not in message
    return message


def test_a_truth_with_a_map_has_its_own_dimension():
    scenario = parse_model(_text(state_names='["x", "g"]'), SOURCE)
    truth = scenario.truth
    assert isinstance(truth, MappedTruthModel)
    assert (truth.state_dim, truth.measurement_dim, truth.error_dim) == (2, 1, 1)
    assert scenario.filter.state_dim == 1 and not isinstance(scenario.filter, MappedTruthModel)
    np.testing.assert_array_equal(scenario.truth_map, [[1.0, 0.0]])
    np.testing.assert_array_equal(truth.phi, [[1.0, 0.0], [0.0, 0.9]])
    assert truth.state_names == ("x", "g")
    assert (truth.steps_per_update, truth.sample_period) == (2, 1.0)
    assert parse_model(_text(), SOURCE).truth.state_names is None


def test_a_truth_without_a_map_is_unchanged():
    scenario = load_model_file(EXAMPLES / "constant_velocity_mistuned.toml")
    assert not isinstance(scenario.truth, MappedTruthModel) and scenario.truth_map is None
    assert set(section_values(scenario)["truth"]) == {*MODEL_KEYS, "steps_per_update", "sample_period"}


def test_the_summary_settings_keep_the_map_and_rebuild_the_scenario():
    scenario = parse_model(_text(state_names='["x", "g"]'), SOURCE)
    settings = to_jsonable(section_values(scenario))
    assert settings["truth"]["map"] == [[1.0, 0.0]] and settings["truth"]["state_names"] == ["x", "g"]
    assert settings["truth"]["phi"] == [[1.0, 0.0], [0.0, 0.9]] and settings["filter"]["phi"] == [[1.0]]
    rebuilt = CustomModelScenario.from_settings(settings)
    assert isinstance(rebuilt.truth, MappedTruthModel) and rebuilt.truth.state_names == ("x", "g")
    for key in (*MODEL_KEYS, "map"):
        np.testing.assert_array_equal(getattr(rebuilt.truth, key), getattr(scenario.truth, key), err_msg=key)
    for key in MODEL_KEYS:
        np.testing.assert_array_equal(getattr(rebuilt.filter, key), getattr(scenario.filter, key), err_msg=key)
    assert to_jsonable(section_values(rebuilt)) == settings


def test_set_filter_never_touches_a_mapped_truth():
    plain = parse_model(_text(), SOURCE)
    retuned = parse_model(_text(), SOURCE, ["filter.w=[[0.04]]", "filter.phi=[[0.5]]", "filter.x0=[3.0]"])
    np.testing.assert_array_equal(retuned.filter.w, [[0.04]])
    assert to_jsonable(section_values(retuned)["truth"]) == to_jsonable(section_values(plain)["truth"])
    # and a key the table lacks is not filled from the file's top level
    message = _error(_text(gamma=None), ["filter.gamma=[[2.0]]"])
    assert message.startswith(f"{SOURCE}: truth.map: expected all of phi, gamma, h, w, v, x0, m0 in [truth]")
    assert message.endswith("got no gamma")


def test_set_truth_map_and_state_names():
    scenario = parse_model(_text(), SOURCE, ["truth.map=[[2.0, 0.0]]", 'truth.state_names=["a", "b"]'])
    np.testing.assert_array_equal(scenario.truth_map, [[2.0, 0.0]])
    assert scenario.truth.state_names == ("a", "b")
    message = _error(_text(), ["truth.map=[[1.0, 0.0, 0.0]]"])
    assert message == "truth.map: expected 2 columns to match the truth's phi, got shape (1, 3)"


@pytest.mark.parametrize(
    "changes, expected",
    [
        (
            {"gamma": None, "x0": None},
            "truth.map: expected all of phi, gamma, h, w, v, x0, m0 in [truth] beside it (a truth with a map has "
            "its own states and takes nothing from the filter), got no gamma, x0",
        ),
        ({"map": "[[1.0, 0.0], [0.0, 1.0]]"}, "truth.map: expected shape (1, 2) (a row per filter state, a column per truth state), got (2, 2)"),
        ({"map": "[[1.0, 0.0, 0.0]]"}, "truth.map: expected 2 columns to match the truth's phi, got shape (1, 3)"),
        ({"map": "[1.0, 0.0]"}, "truth.map: expected a matrix, an array of rows such as [[1.0, 0.0], [0.0, 1.0]], got [1.0, 0.0]"),
        ({"map": '"identity"'}, "truth.map: expected a matrix, an array of rows such as [[1.0, 0.0], [0.0, 1.0]], got 'identity'"),
        ({"map": "[[nan, 0.0]]"}, "truth.map: expected finite numbers, got [[nan, 0.0]]"),
        ({"map": "[[1.0, true]]"}, "truth.map: expected numbers, got True (a boolean) in row 1"),
        ({"state_names": '["x"]'}, "truth.state_names: expected 2 entries (one per truth state), got 1: ['x']"),
        ({"state_names": "[1, 2]"}, "truth.state_names: expected an array of strings, got [1, 2]"),
        ({"gamma": "[[1.0]]"}, "truth.gamma: expected 2 rows to match phi, got shape (1, 1)"),
        ({"h": "[[1.0, 1.0], [0.0, 1.0]]", "v": "[[1.0, 0.0], [0.0, 1.0]]"}, "truth.h: expected shape (1, 2) (a row per measurement of the filter, a column per truth state), got (2, 2)"),
        ({"m0": "[[4.0, 0.0], [0.0, -1.0]]"}, "truth.m0: expected a positive semi-definite covariance, got [[4.0, 0.0], [0.0, -1.0]] (eigenvalue -1)"),
        ({"q": "[[1.0]]"}, "truth.q: expected a key of a [truth] with a map (map, state_names, phi, gamma, h, w, v, x0, m0, b), got an unknown key"),
    ],
    ids=["missing", "rows", "columns", "flat", "string", "nan", "boolean", "names-count", "names-type", "gamma", "h-rows", "m0", "unknown"],
)
def test_a_bad_map_input_is_one_line_naming_the_key(changes, expected):
    assert _error(_text(**changes)) == f"{SOURCE}: {expected}"


def test_state_names_need_a_map():
    assert _error(_text(map=None, state_names='["x", "g"]')) == (
        f"{SOURCE}: truth.state_names: expected a map beside it (state_names names the states of a truth with "
        "its own dimension), got no truth.map"
    )


def test_the_colored_gps_example_holds_the_seed_filter():
    from kalcal.scenarios.accel_gps.settings import AccelGpsScenario

    scenario = load_model_file(EXAMPLES / "accel_gps_colored_gps.toml")
    seed = AccelGpsScenario().filter_model()
    for key in MODEL_KEYS:
        np.testing.assert_allclose(getattr(scenario.filter, key), getattr(seed, key), rtol=1e-15, err_msg=key)
    assert (scenario.filter.steps_per_update, scenario.filter.sample_period) == (seed.steps_per_update, seed.sample_period)
    truth = scenario.truth
    assert truth.state_dim == 4 and scenario.truth_map.shape == (3, 4)
    # g: first-order Gauss-Markov, tau = 20 s and 1 m stationary std, at the 200 Hz sample
    decay = truth.phi[3, 3]
    np.testing.assert_allclose(-seed.sample_period / np.log(decay), 20.0, rtol=1e-12)
    np.testing.assert_allclose(truth.w[1, 1] / (1.0 - decay**2), 1.0, rtol=1e-12)
    np.testing.assert_allclose(truth.m0[3, 3], 1.0)
    np.testing.assert_array_equal(truth.v, seed.v)  # the white part is the filter's
