"""Model files with a [data] table, known inputs, h entries naming data columns and diffuse states: parsing,
every new error, the settings and Model round trips, and the binding of a file to a log (CSV, DataFrame,
ROS bag) against hand-built arrays."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from kalcal import Model
from kalcal.errors import ConfigError, DataError
from kalcal.io.results import to_jsonable
from kalcal.models.config import section_values
from kalcal.scenarios.model_file.model import CustomModelScenario, is_custom_settings, model_fields, parse_model
from kalcal.scenarios.protocol import require

SOURCE = "seed.toml"

#: seed 003 (a sensor's scale and bias against a reference) as a model file: h_j = [reference_j, 1]
SCALE_BIAS = """
name = "scale-bias-file"
sample_period = 0.01
phi = [[1.0, 0.0], [0.0, 1.0]]
gamma = [[1.0], [0.0]]
w = [[0.0]]
h = [["reference", 1.0]]
v = [[0.04]]
x0 = [0.0, 0.0]
m0 = [[0.0, 0.0], [0.0, 0.0]]
diffuse = ["scale", "bias"]
state_names = ["scale", "bias"]

[data]
time = "t"
measurements = ["sensor"]
"""

#: a constant-velocity tracker driven by a known acceleration, its position measured with a std per row
TRACKER = {
    "sample_period": "0.1",
    "phi": "[[1.0, 0.1], [0.0, 1.0]]",
    "gamma": "[[0.005], [0.1]]",
    "b": "[[0.005], [0.1]]",
    "w": "[[0.04]]",
    "h": "[[1.0, 0.0], [0.0, 1.0]]",
    "v": "[[4.0, 0.4], [0.4, 1.0]]",
    "x0": "[0.0, 10.0]",
    "m0": "[[25.0, 0.0], [0.0, 1.0]]",
}
TRACKER_DATA = {"time": '"t"', "measurements": '["pos", "vel"]', "inputs": '["acc"]', "stds": '["pos_std", ""]'}


def _text(top=None, data=TRACKER_DATA, truth=None, **changes) -> str:
    values = {**(top or TRACKER), **changes}
    lines = [f"{key} = {value}" for key, value in values.items() if value is not None]
    for name, table in (("data", data), ("truth", truth)):
        if table is not None:
            lines += [f"[{name}]"] + [f"{key} = {value}" for key, value in table.items() if value is not None]
    return "\n".join(lines) + "\n"


def _error(text: str, assignments=()) -> str:
    with pytest.raises(ConfigError) as info:
        parse_model(text, SOURCE, assignments)
    message = str(info.value)
    assert "\n" not in message
    return message


def _log(rows: int = 5) -> pd.DataFrame:
    t = np.arange(rows) * 0.1
    return pd.DataFrame({
        "t": t, "pos": 1.0 + t, "vel": np.where(np.arange(rows) == 2, np.nan, 2.0 + t), "acc": 0.5 * t,
        "pos_std": 1.0 + np.arange(rows),
    })  # fmt: skip


# --- parsing ---------------------------------------------------------------------------------------------


def test_seed_003_as_a_model_file_parses_with_rows_from_data_and_diffuse_states():
    scenario = parse_model(SCALE_BIAS, SOURCE)
    f = scenario.filter
    assert f.h_columns == (("reference", ""),) and f.data_columns == ("reference",)
    assert np.isnan(f.h[0, 0]) and f.h[0, 1] == 1.0  # never a number where the data gives one
    assert f.diffuse == ("scale", "bias") and f.input_dim == 0
    assert scenario.model.updates is None and scenario.data.measurements == ("sensor",) and scenario.data.time == "t"
    assert scenario.data.step_tolerance == 0.01
    # its rows come from a log: verify and analyze are refused in one line naming --data
    with pytest.raises(ConfigError) as info:
        require(scenario, "verify")
    assert str(info.value) == (
        f"a model file ({SOURCE}): its h names data columns (reference): its rows come from a log, so it is not "
        "verified without one (--data LOG)"
    )
    assert "analyze" not in scenario.capabilities.commands and "report" in scenario.capabilities.commands


def test_todays_files_keep_verify_and_their_step_grid():
    from kalcal.scenarios import load_model_file
    from tests.models.test_custom_model import EXAMPLES

    scenario = load_model_file(EXAMPLES / "constant_velocity.toml")
    assert scenario.data is None and scenario.without_log() == ""
    assert scenario.capabilities.commands == frozenset({"verify", "analyze", "sweep", "report"})
    filt, truth = scenario.step_grid()
    m, k = 10, 30
    assert truth is None and filt.steps == k * m + 1
    measured = np.all(np.isfinite(filt.h), axis=(1, 2))
    np.testing.assert_array_equal(np.flatnonzero(measured), np.arange(1, k + 1) * m)  # first fix after m steps
    np.testing.assert_array_equal(filt.h[m], scenario.filter.h)
    np.testing.assert_array_equal(filt.v[m], scenario.filter.v)
    np.testing.assert_allclose(filt.times, np.arange(k * m + 1) * 0.1, rtol=1e-15)
    np.testing.assert_array_equal(filt.m0, scenario.filter.m0)
    assert filt.b.shape == (2, 0) and filt.u.shape == (k * m + 1, 0) and not filt.diffuse.any()


def test_the_step_grid_filter_has_the_fixed_gain_problems_covariances():
    """The same model two ways: the Kalman covariance recursion over the grid's rows (predict every row,
    update where H_j is finite) equals the verify problem's P_k at every update."""
    from kalcal.scenarios import load_model_file
    from tests.models.test_custom_model import EXAMPLES

    scenario = load_model_file(EXAMPLES / "constant_velocity.toml")
    filt, _ = scenario.step_grid()
    problem = scenario.problem()
    p = filt.m0.copy()
    covariances = []
    for j in range(filt.steps):
        if j:
            p = filt.phi @ p @ filt.phi.T + filt.gamma @ filt.w @ filt.gamma.T
        if np.all(np.isfinite(filt.h[j])):
            h = filt.h[j]
            s = h @ p @ h.T + filt.v[j]
            gain = np.linalg.solve(s, h @ p).T
            a = np.eye(2) - gain @ h
            p = a @ p @ a.T + gain @ filt.v[j] @ gain.T
            covariances.append(p)
    np.testing.assert_allclose(np.array(covariances), problem.schedule.posterior_cov, rtol=1e-10, atol=1e-12)


ERRORS = [
    ({"b": None}, TRACKER_DATA, "b: expected a (2, 1) matrix beside data.inputs, got nothing (inputs need their b)"),
    ({}, {**TRACKER_DATA, "inputs": None}, "data.inputs: expected 1 column names, one per column of b, got nothing (b needs its inputs)"),
    ({}, {**TRACKER_DATA, "inputs": '["a", "b"]'}, "data.inputs: expected 1 entries (one per column of b), got 2: ['a', 'b']"),
    ({"b": "[[1.0]]"}, TRACKER_DATA, "b: expected 2 rows to match phi, got shape (1, 1)"),
    ({"phi": '[["a", 0.0], [0.0, 1.0]]'}, TRACKER_DATA, "phi: expected numbers, got 'a' (a string) in row 1"),
    ({"h": '[["", 0.0], [0.0, 1.0]]'}, TRACKER_DATA, "h: expected a data column's name or a number, got '' (a string) in row 1"),
    ({"diffuse": '["speed"]'}, TRACKER_DATA, "diffuse: expected state names (of x1, x2), got 'speed'"),
    ({"diffuse": '["x2"]'}, TRACKER_DATA, "m0: expected zero rows and columns for the diffuse states (x2: no prior information), got [[25.0, 0.0], [0.0, 1.0]]"),
    ({"diffuse": '["x1", "x1"]', "m0": "[[0.0, 0.0], [0.0, 1.0]]"}, TRACKER_DATA, "diffuse: expected each state once, got ['x1', 'x1']"),
    ({}, {**TRACKER_DATA, "measurements": None}, "data.measurements: expected 2 column names, one per row of h, got nothing (a required key)"),
    ({}, {**TRACKER_DATA, "measurements": '["pos"]'}, "data.measurements: expected 2 entries (one per row of h), got 1: ['pos']"),
    ({}, {**TRACKER_DATA, "measurements": '["pos", ""]'}, "data.measurements: expected non-empty column names, got ['pos', '']"),
    ({}, {**TRACKER_DATA, "stds": '["pos_std"]'}, "data.stds: expected 2 entries (one per measurement), got 1: ['pos_std']"),
    ({}, {**TRACKER_DATA, "time": '""'}, "data.time: expected a column name (leave time out for row j at j * sample_period), got ''"),
    ({}, {**TRACKER_DATA, "step_tolerance": "0.5"}, "data.step_tolerance: expected a fraction of sample_period below 0.5, got 0.5"),
    ({}, {**TRACKER_DATA, "step_tolerance": "0"}, "data.step_tolerance: expected a positive number, got 0"),
    ({}, {**TRACKER_DATA, "rate": "5"}, "data.rate: expected a key of [data] (time, measurements, inputs, stds, step_tolerance), got an unknown key"),
    ({"updates": "3"}, TRACKER_DATA, "steps_per_update: expected a positive integer beside updates (the model steps between two of them), got nothing"),
    ({"h": '[["pos_gain", 0.0], [0.0, 1.0]]', "b": None, "steps_per_update": "1", "updates": "3"}, None, "data: expected a [data] table beside an h that names data columns (the log's columns feed the model), got none (h names pos_gain)"),
    ({"steps_per_update": "1", "updates": "3"}, None, "data.inputs: expected 1 column names beside b (the known inputs), got no [data] table"),
]


@pytest.mark.parametrize("changes, data, expected", ERRORS, ids=[e[2].split(":")[0] + str(i) for i, e in enumerate(ERRORS)])
def test_every_new_error_is_one_line_naming_the_file_and_key(changes, data, expected):
    assert _error(_text(data=data, **changes)) == f"{SOURCE}: {expected}"


def test_a_file_without_data_still_needs_its_timing():
    text = _text(data=None, b=None)
    assert _error(text) == f"{SOURCE}: steps_per_update: expected a positive integer, got nothing (a required key)"


def test_truth_inputs_decide_whether_verify_needs_a_log():
    timing = {"steps_per_update": "1", "updates": "3"}
    data = {**TRACKER_DATA, "stds": None}
    same = parse_model(_text(data=data, **timing), SOURCE)
    assert same.without_log() == "" and "verify" in same.capabilities.commands  # the error does not depend on u
    other = parse_model(_text(data=data, truth={"b": "[[0.0], [0.2]]"}, **timing), SOURCE)
    assert other.differing() == ("b",)
    assert "its truth's inputs (b) differ from the filter's, so the filter's error depends on the inputs u" in other.without_log()
    assert _error(_text(data=data, truth={"b": "[[0.0, 1.0], [0.2, 0.0]]"}, **timing)) == (
        f"{SOURCE}: truth.b: expected 1 column like the filter's b, got shape (2, 2)"
    )
    stds = parse_model(_text(**timing), SOURCE)
    assert stds.without_log().startswith("its measurement stds come from data columns (pos_std)")
    no_updates = parse_model(_text(data=data), SOURCE)
    assert no_updates.without_log().startswith("it sets no updates")


# A diffuse filter is verified where its [truth] gives the world's m0 (tests/models/test_model_file_diffuse.py);
# without one, the one line that simulate gives too, naming what to add.
def test_a_diffuse_filter_without_a_truth_m0_is_refused_by_verify_and_verified_with_one():
    timing = {"steps_per_update": "1", "updates": "3", "b": None, "diffuse": '["x1"]', "m0": "[[0.0, 0.0], [0.0, 1.0]]"}
    data = {"measurements": '["pos", "vel"]'}
    expected = (
        f"a model file ({SOURCE}): its filter starts diffuse in x1 and it has no [truth] m0: give [truth] m0 (the "
        "world's proper prior) to verify or analyze it"
    )
    for truth in ({}, {"truth": {"w": "[[0.09]]"}}):
        scenario = parse_model(_text(data=data, **truth, **timing), SOURCE)
        for command in ("verify", "analyze"):
            with pytest.raises(ConfigError) as info:
                require(scenario, command)
            assert str(info.value) == expected
    proper = parse_model(_text(data=data, truth={"m0": "[[25.0, 0.0], [0.0, 1.0]]"}, **timing), SOURCE)
    require(proper, "verify")
    require(proper, "analyze")


# --- round trips ------------------------------------------------------------------------------------------


def _same(a: CustomModelScenario, b: CustomModelScenario) -> None:
    assert a.model == b.model and a.data == b.data
    for x, y in ((a.filter, b.filter), (a.truth, b.truth)):
        for key in ("phi", "gamma", "h", "w", "v", "x0", "m0", "b"):
            np.testing.assert_array_equal(getattr(x, key), getattr(y, key), err_msg=key)
        assert (x.h_columns, x.diffuse, x.steps_per_update, x.sample_period) == (
            y.h_columns, y.diffuse, y.steps_per_update, y.sample_period
        )


@pytest.mark.parametrize("text", [SCALE_BIAS, _text(truth={"b": "[[0.0], [0.2]]", "w": "[[0.09]]"})], ids=["seed-003", "tracker"])
def test_settings_round_trip_through_json_with_the_data_section(text):
    scenario = parse_model(text, SOURCE)
    settings = json.loads(json.dumps(to_jsonable(section_values(scenario))))
    assert is_custom_settings(settings) and set(settings) == {"model", "filter", "truth", "data"}
    _same(CustomModelScenario.from_settings(settings), scenario)


@pytest.mark.parametrize("text", [SCALE_BIAS, _text(truth={"b": "[[0.0], [0.2]]", "w": "[[0.09]]"})], ids=["seed-003", "tracker"])
def test_model_fields_build_the_same_scenario_through_kalcal_model(text):
    scenario = parse_model(text, SOURCE)
    fields = model_fields(scenario)
    rebuilt = Model(**fields).scenario()
    _same(rebuilt, scenario)
    assert "[data]" in Model(**fields).document()


def test_kalcal_model_takes_b_diffuse_and_data():
    model = Model(
        phi=[[1.0, 0.0], [0.0, 1.0]], gamma=[[1.0], [0.0]], w=[[0.0]], h=[["reference", 1.0]], v=[[0.04]],
        x0=[0.0, 0.0], m0=[[0.0, 0.0], [0.0, 0.0]], diffuse=["scale", "bias"], state_names=["scale", "bias"],
        data={"measurements": ["sensor"], "time": "t"}, sample_period=0.01, name="scale-bias-file",
    )  # fmt: skip
    _same(model.scenario(), parse_model(SCALE_BIAS, "<Model>"))
    with pytest.raises(ConfigError, match=r"^<Model>: data: expected a \[data\] table beside an h that names"):
        Model(**{**model.__dict__, "data": None, "steps_per_update": 1, "updates": 3}).scenario()


def test_set_keys_reach_b_diffuse_and_the_data_table():
    text = _text()
    scenario = parse_model(text, SOURCE, ["filter.b=[[0.0], [1.0]]", 'data.measurements=["p", "v"]', "data.step_tolerance=0.05"])
    assert scenario.filter.b.tolist() == [[0.0], [1.0]] and scenario.truth.b.tolist() == [[0.005], [0.1]]
    assert scenario.data.measurements == ("p", "v") and scenario.data.step_tolerance == 0.05
    diffuse = parse_model(text, SOURCE, ['filter.diffuse=["x1"]', "filter.m0=[[0.0, 0.0], [0.0, 1.0]]"])
    assert diffuse.filter.diffuse == ("x1",)
    assert _error(text, ["data.step_tolerance=2"]) == "data.step_tolerance: expected a fraction of sample_period below 0.5, got 2.0"
    assert _error(text, ["data.rate=2"]).startswith("data.rate: expected a model file's setting (")


# --- the binding -------------------------------------------------------------------------------------------


def _expected_arrays(frame: pd.DataFrame):
    """The tracker's rows built by hand: V_j = D_j V D_j with D_j = diag(pos_std_j / 2, 1)."""
    v = np.array([[4.0, 0.4], [0.4, 1.0]])
    vs = []
    for std in frame["pos_std"].to_numpy():
        d = np.diag([std / 2.0, 1.0])
        vs.append(d @ v @ d)
    z = frame[["pos", "vel"]].to_numpy()
    return z, np.array(vs), frame[["acc"]].to_numpy()


@pytest.mark.parametrize("kind", ["csv", "frame", "csv.gz"])
def test_binding_to_a_table_gives_the_hand_built_arrays(tmp_path, kind):
    scenario = parse_model(_text(), SOURCE)
    frame = _log()
    log = frame
    if kind != "frame":
        log = tmp_path / f"log.{kind}"
        frame.to_csv(log, index=False)
    bound = scenario.bind(log)
    z, v, u = _expected_arrays(frame)
    np.testing.assert_array_equal(bound.z, z)
    np.testing.assert_allclose(bound.filter.v, v, rtol=1e-15)
    np.testing.assert_array_equal(bound.filter.u, u)
    np.testing.assert_array_equal(bound.filter.h, np.broadcast_to(np.eye(2), (5, 2, 2)))
    np.testing.assert_array_equal(bound.times, frame["t"].to_numpy())
    np.testing.assert_array_equal(bound.filter.b, [[0.005], [0.1]])
    assert bound.truth is None and bound.source == (str(log) if kind != "frame" else "<data DataFrame>")
    from kalcal.core.timevarying import measured_components

    assert measured_components(bound.filter, bound.z)[2].tolist() == [True, False]  # the empty cell only


def test_binding_seed_003_takes_each_rows_h_from_its_column():
    scenario = parse_model(SCALE_BIAS, SOURCE)
    reference = np.array([1.0, np.nan, 3.0, 4.0])
    frame = pd.DataFrame({"t": [0.0, 0.01, 0.02, 0.03], "reference": reference, "sensor": [2.1, 3.0, 6.2, np.nan]})
    bound = scenario.bind(frame)
    np.testing.assert_array_equal(bound.filter.h[:, 0, 0], reference)
    np.testing.assert_array_equal(bound.filter.h[:, 0, 1], 1.0)
    assert bound.filter.diffuse.tolist() == [True, True]
    from kalcal.core.timevarying import measured_components

    # row 2's regressor is empty, row 4's measurement: neither is measured
    assert measured_components(bound.filter, bound.z)[:, 0].tolist() == [True, False, True, False]


def test_binding_a_truth_of_its_own_gives_its_model_too():
    scenario = parse_model(_text(truth={"b": "[[0.0], [0.2]]"}), SOURCE)
    bound = scenario.bind(_log())
    assert bound.truth is not None
    np.testing.assert_array_equal(bound.truth.b, [[0.0], [0.2]])
    np.testing.assert_array_equal(bound.truth.u, bound.filter.u)


def test_binding_without_time_puts_row_j_at_j_periods():
    scenario = parse_model(_text(data={**TRACKER_DATA, "time": None}), SOURCE)
    bound = scenario.bind(_log().drop(columns="t"))
    np.testing.assert_allclose(bound.times, np.arange(5) * 0.1, rtol=1e-15)


def _bind_error(frame, text=None, **kwargs) -> str:
    scenario = parse_model(text or _text(), SOURCE)
    with pytest.raises(DataError) as info:
        scenario.bind(frame, **kwargs)
    message = str(info.value)
    assert "\n" not in message
    return message


def test_every_check_of_a_log_names_it():
    frame = _log()
    assert _bind_error(frame.drop(columns="acc")) == (
        "<data DataFrame>: missing column 'acc' (columns: t, pos, vel, pos_std)"
    )
    bad = frame.astype({"pos": object})
    bad.loc[3, "pos"] = "x"
    assert _bind_error(bad) == "<data DataFrame>: row 4, column 'pos': not a number: 'x'"
    back = frame.copy()
    back.loc[3, "t"] = 0.15
    assert _bind_error(back) == "<data DataFrame>: row 4, column 't': time 0.15 does not increase (previous row 0.2)"
    off = frame.copy()
    off.loc[3, "t"] = 0.302  # 0.102 s after row 3: 2% off the 0.1 s period
    assert _bind_error(off) == (
        "<data DataFrame>: row 4, column 't': time step 0.102 s from row 3 is off sample_period 0.1 s by more than "
        "step_tolerance 0.01 (a fraction of it): the model steps once per row"
    )
    assert parse_model(_text(data={**TRACKER_DATA, "step_tolerance": "0.05"}), SOURCE).bind(off).times[3] == 0.302
    nan_input = frame.copy()
    nan_input.loc[1, "acc"] = np.nan
    assert _bind_error(nan_input) == "<data DataFrame>: row 2, column 'acc': value is nan, expected a finite number"
    zero_std = frame.copy()
    zero_std.loc[4, "pos_std"] = 0.0
    assert _bind_error(zero_std) == (
        "<data DataFrame>: row 5, column 'pos_std': std 0.0, expected a positive number (the std of measurement 'pos')"
    )
    nan_std = frame.copy()
    nan_std.loc[0, "pos_std"] = np.nan  # where pos is measured
    assert _bind_error(nan_std).startswith("<data DataFrame>: row 1, column 'pos_std': std nan, expected a positive")


def test_a_file_without_data_is_not_bound():
    from kalcal.scenarios import load_model_file
    from tests.models.test_custom_model import EXAMPLES

    scenario = load_model_file(EXAMPLES / "constant_velocity.toml")
    with pytest.raises(ConfigError, match=r"constant_velocity.toml: data: expected a \[data\] table naming the log's columns"):
        scenario.bind(_log())


def test_binding_a_ros_bag_topic(tmp_path):
    from tests._logfiles import write_imu_bag

    stamps = 1_700_000_000_000_000_000 + np.arange(6) * 10_000_000  # 100 Hz
    accel = np.column_stack([np.arange(6) * 0.5, np.ones(6), np.zeros(6)])
    bag = write_imu_bag(tmp_path / "imu.bag", stamps, accel)
    text = f"""
sample_period = 0.01
phi = [[1.0]]
gamma = [[1.0]]
w = [[0.01]]
h = [["/imu.linear_acceleration.y"]]
v = [[0.25]]
x0 = [0.0]
m0 = [[1.0]]
[data]
time = "time"
measurements = ["/imu.linear_acceleration.x"]
"""
    bound = parse_model(text, SOURCE).bind(bag)
    np.testing.assert_array_equal(bound.z[:, 0], accel[:, 0])
    np.testing.assert_array_equal(bound.filter.h[:, 0, 0], accel[:, 1])
    np.testing.assert_allclose(bound.times, np.arange(6) * 0.01, atol=1e-12)
    assert bound.source == f"{bag} topic /imu"
    wrong = text.replace('measurements = ["/imu.linear_acceleration.x"]', 'measurements = ["/imu.linear_acceleration.w"]')
    with pytest.raises(DataError, match=rf"^{bag} topic /imu: missing column '/imu.linear_acceleration.w' \(columns: time, "):
        parse_model(wrong, SOURCE).bind(bag)
    slow = text.replace("sample_period = 0.01", "sample_period = 0.02")
    with pytest.raises(DataError, match=rf"^{bag} topic /imu: row 2, column 'time': time step 0.01 s from row 1 is off"):
        parse_model(slow, SOURCE).bind(bag)


def test_the_docs_seed_003_file_is_the_one_tested_here():
    from pathlib import Path

    text = (Path(__file__).resolve().parents[2] / "docs" / "custom-models.md").read_text(encoding="utf-8")
    block = next(b for b in text.split("```toml")[1:] if "scale-bias-file" in b).split("```")[0]
    _same(parse_model(block, SOURCE), parse_model(SCALE_BIAS, SOURCE))


def test_a_truth_h_may_name_columns_and_is_bound_from_its_own():
    text = _text(truth={"h": '[["gain", 0.0], [0.0, 1.0]]'})
    scenario = parse_model(text, SOURCE)
    assert scenario.truth.h_columns == (("gain", ""), ("", "")) and scenario.filter.h_columns == ()
    assert scenario.differing() == ("h",)
    frame = _log().assign(gain=np.linspace(0.9, 1.1, 5))
    bound = scenario.bind(frame)
    np.testing.assert_array_equal(bound.truth.h[:, 0, 0], frame["gain"].to_numpy())
    np.testing.assert_array_equal(bound.filter.h[:, 0, 0], 1.0)


# --- summary keys of a file without the new features -------------------------------------------------------------


def test_a_summary_leaves_out_empty_inputs_columns_and_diffuse_and_rebuilds_both_forms():
    """A file without inputs, data-named rows of h or diffuse states writes the keys a time-invariant model
    wrote before they existed, so an old run's checkpoint fingerprint is unchanged; the old form and the form
    with the keys (as such runs wrote them for a while) both rebuild the same scenario."""
    import dataclasses

    from kalcal.core.model import LinearGaussianModel
    from kalcal.montecarlo.checkpoint import fingerprint

    old_keys = {f.name for f in dataclasses.fields(LinearGaussianModel)}
    scenario = parse_model(_text(data=None, truth={"w": "[[0.09]]"}, b=None, steps_per_update="1", updates="5"), SOURCE)
    settings = json.loads(json.dumps(to_jsonable(section_values(scenario))))
    assert set(settings["filter"]) == set(settings["truth"]) == old_keys
    # the fingerprint a checkpoint carries is that of the settings a LinearGaussianModel's fields give
    old = {section: (to_jsonable(dataclasses.asdict(LinearGaussianModel(**{k: getattr(getattr(scenario, section), k) for k in old_keys})))
                     if section in ("filter", "truth") else value) for section, value in settings.items()}
    assert fingerprint({"settings": settings}) == fingerprint({"settings": json.loads(json.dumps(old))})
    with_keys = {**settings, **{s: {**settings[s], "b": [[]] * 2, "h_columns": [], "diffuse": []} for s in ("filter", "truth")}}
    for form in (settings, with_keys):
        _same(CustomModelScenario.from_settings(form), scenario)
    # a file with them keeps them (and only those it has)
    inputs = parse_model(_text(truth={"b": "[[0.0], [0.2]]", "w": "[[0.09]]"}), SOURCE)
    sections = section_values(inputs)
    assert "b" in sections["filter"] and "b" in sections["truth"] and "diffuse" not in sections["filter"]
    assert {"h_columns", "diffuse"} <= set(section_values(parse_model(SCALE_BIAS, SOURCE))["filter"])
