"""``kalcal sweep MODEL.toml --set KEY=v1,v2`` (and ``--data LOG``): one verify per value of one number of the file.

``--set`` takes one number of a model file's matrix (``filter.v=0.5``, ``filter.m0.2=16``,
``truth.phi.1.2=0.2``); a sweep's run of each value is that verify, bit for bit at the same seed, over the
same log where one is given, and each run's folder is one ``kalcal report`` rebuilds. A key that names a
matrix of several numbers and a timing key over a log are refused in one line; a diffuse filter is swept
where verify takes it (a [truth] m0 given).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import kalcal
from kalcal.api.sweep import sweep_settings
from kalcal.scenarios.model_file.model import parse_model
from tests._helpers import invoke as _invoke

CV = """
name = "cv"
sample_period = 0.1
steps_per_update = 10
updates = 12
phi   = [[1.0, 0.1], [0.0, 1.0]]
gamma = [[0.005], [0.1]]
h     = [[1.0, 0.0]]
w     = [[0.04]]
v     = [[4.0]]
x0    = [0.0, 10.0]
m0    = [[25.0, 3.0], [3.0, 1.0]]
"""
# the same model over a log: h's first entry from the column c (all ones), a fix every 10th row
CV_LOG = CV.replace('h     = [[1.0, 0.0]]', 'h     = [["c", 0.0]]') + '\n[data]\nmeasurements = ["z"]\n'
#: the parts of a summary that differ between two runs of the same numbers (wall time, the command line)
_RUN_RECORD = ("timing", "command")


def _cv_log(path: Path, count: int = 121, every: int = 10) -> Path:
    z = np.full(count, np.nan)
    z[every::every] = 0.0  # the values are never read: only which rows are measured
    pd.DataFrame({"z": z, "c": np.ones(count)}).to_csv(path, index=False)
    return path


def _numbers(summary_path: Path) -> dict:
    summary = json.loads(Path(summary_path).read_text())
    return {key: value for key, value in summary.items() if key not in _RUN_RECORD}


# --- --set takes one number of a matrix --------------------------------------------------------------


def test_set_takes_one_number_of_a_matrix():
    base = parse_model(CV, "cv.toml")
    one = parse_model(CV, "cv.toml", ["filter.v=0.5"])
    assert np.array_equal(one.filter.v, [[0.5]]) and np.array_equal(one.truth.v, base.truth.v)  # the world held
    assert np.array_equal(one.filter.v, parse_model(CV, "cv.toml", ["filter.v=[[0.5]]"]).filter.v)
    # a diagonal entry of a covariance holds its correlation: C_12 / sqrt(C_11 C_22) = 3 / 5 before and after
    m0 = parse_model(CV, "cv.toml", ["filter.m0.2=16"]).filter.m0
    assert m0.tolist() == [[25.0, 12.0], [12.0, 16.0]]  # S = diag(1, 4): C_12 = 3 x 4 (docs/custom-models.md)
    assert m0[0, 1] == m0[1, 0] and m0[0, 1] / np.sqrt(m0[0, 0] * m0[1, 1]) == pytest.approx(3.0 / 5.0, rel=1e-15)
    # a truth entry sets the truth's matrix (the file's, which [truth] follows) and leaves the filter's
    truth = parse_model(CV, "cv.toml", ["truth.phi.1.2=0.2", "filter.x0.2=3"])
    assert np.array_equal(truth.truth.phi, [[1.0, 0.2], [0.0, 1.0]]) and np.array_equal(truth.filter.phi, base.filter.phi)
    assert np.array_equal(truth.filter.x0, [0.0, 3.0]) and np.array_equal(truth.truth.x0, base.truth.x0)


@pytest.mark.parametrize(
    ("assignment", "words"),
    [
        ("filter.m0=3", "m0 is 2 x 2; one of its numbers is set by filter.m0.1, filter.m0.2"),
        ("filter.m0.1.2=1", "an off-diagonal entry is held at its correlation"),
        ("filter.phi.3.1=1", "a 1-based row of phi in 1..2"),
        ("filter.phi.1=1", "an entry filter.phi.I.J"),
        ("truth.v=-1", "a variance >= 0"),
        ("filter.m0.2=-1", "a variance >= 0"),
    ],
)
def test_set_of_one_number_refuses_what_names_no_number(assignment, words):
    with pytest.raises(kalcal.errors.ConfigError) as error:
        parse_model(CV, "cv.toml", [assignment])
    assert str(error.value).startswith(assignment.split("=")[0] + ": ") and words in str(error.value)


def test_set_refuses_an_entry_of_h_that_names_a_data_column():
    with pytest.raises(kalcal.errors.ConfigError, match=r"h.1.1: .*the data column 'c'"):
        parse_model(CV_LOG, "cv.toml", ["filter.h.1.1=2"])


def test_a_fixed_matrix_setting_beside_the_swept_key_is_not_a_list_of_values():
    key, values, fixed = sweep_settings(["filter.m0=[[4, 0], [0, 1]]", "filter.v=1,4"])
    assert (key, values, fixed) == ("filter.v", ["1", "4"], {"filter.m0": "[[4, 0], [0, 1]]"})


# --- the sweep: each value's run is verify --set key=value ------------------------------------------


def test_each_value_of_a_sweep_is_the_verify_of_that_value_and_report_rebuilds_it(tmp_path):
    model = tmp_path / "cv.toml"
    model.write_text(CV)
    result = kalcal.sweep(model, "filter.m0.2", [1, 4], n=200, seed=5, out=tmp_path / "sw")
    assert result.values == ["1", "4"] and list(result.table["filter.m0.2"]) == [1.0, 4.0]
    for value, run in zip(result.values, result.runs):
        alone = tmp_path / f"alone{value}"
        kalcal.verify(model, 200, seed=5, settings={"filter.m0.2": value}, out=alone)
        assert _numbers(run / "summary.json") == _numbers(alone / "summary.json")  # bit for bit
    # the sweep moved the filter's m0 alone (its correlation held), not the world's
    settings = json.loads((result.runs[1] / "summary.json").read_text())["settings"]
    assert settings["filter"]["m0"] == [[25.0, 6.0], [6.0, 4.0]] and settings["truth"]["m0"] == [[25.0, 3.0], [3.0, 1.0]]
    rebuilt = _invoke("report", result.runs[1])
    assert rebuilt.exit_code == 0, rebuilt.output + rebuilt.stderr
    # the file read already (kalcal.load_model) sweeps as its path does
    again = kalcal.sweep(kalcal.load_model(model), "filter.m0.2", [1, 4], n=200, seed=5, out=tmp_path / "loaded")
    pd.testing.assert_frame_equal(again.table, result.table)


def test_sweep_of_a_model_file_over_a_log_end_to_end(tmp_path):
    model, log = tmp_path / "cv.toml", _cv_log(tmp_path / "log.csv")
    model.write_text(CV_LOG)
    out = tmp_path / "sw"
    result = _invoke("sweep", model, "--data", log, "--set", "filter.v=1,4", "-n", 200, "--seed", 3, "--out", out)
    assert result.exit_code == 0, result.output + result.stderr
    table = pd.read_csv(out / "sweep.csv")
    assert list(table["filter.v"]) == [1.0, 4.0] and (out / "sweep.png").stat().st_size > 0
    digest = None
    for value in ("1", "4"):
        run = out / f"filter.v={value}"
        alone = tmp_path / f"alone{value}"
        verified = _invoke("verify", model, "--data", log, "--set", f"filter.v={value}", "-n", 200, "--seed", 3, "--out", alone)
        assert verified.exit_code == 0, verified.output + verified.stderr
        assert _numbers(run / "summary.json") == _numbers(alone / "summary.json")
        record = json.loads((run / "summary.json").read_text())["settings"]["log"]
        assert record["path"] == str(log.resolve()) and record["sha256"] == (digest := digest or record["sha256"])
    rebuilt = _invoke("report", out / "filter.v=4")
    assert rebuilt.exit_code == 0, rebuilt.output + rebuilt.stderr


def test_sweep_of_a_model_file_without_a_log_from_the_cli(tmp_path):
    model = tmp_path / "cv.toml"
    model.write_text(CV)
    out = tmp_path / "sw"
    result = _invoke("sweep", model, "--set", "filter.steps_per_update=5,10", "-n", 200, "--out", out)
    assert result.exit_code == 0, result.output + result.stderr
    assert list(pd.read_csv(out / "sweep.csv")["filter.steps_per_update"]) == [5, 10]
    assert (out / "sweep.png").stat().st_size > 0 and (out / "sweep.json").is_file()


def test_the_documented_sweep_of_the_constant_velocity_example_passes_at_its_own_w_alone(tmp_path):
    """docs/custom-models.md: the example's truth has w = 0.04; a filter tuned below it is overconfident (NIS
    above its band), above it underconfident (below its band), each at seed 0 and 20,000 realizations."""
    from tests.models.test_custom_model import EXAMPLES

    values = ["0.0025", "0.01", "0.04", "0.16"]
    result = kalcal.sweep(EXAMPLES / "constant_velocity.toml", "filter.w", values, n=20_000, seed=0, out=tmp_path / "sw")
    table = result.table
    assert list(table["verdict"]) == ["fail", "fail", "pass", "fail"]
    nis, lower, upper = (table[f"nis_{part}"].to_numpy() for part in ("statistic", "lower", "upper"))
    assert np.all(nis[:2] > upper[:2]) and lower[2] <= nis[2] <= upper[2] and nis[3] < lower[3]
    assert not table["covariance_passed"][:2].any()


# --- refused in one line ------------------------------------------------------------------------------


def _refused(tmp_path, text, *args):
    model = tmp_path / "cv.toml"
    model.write_text(text)
    out = tmp_path / "refused"
    result = _invoke("sweep", model, *args, "-n", 200, "--out", out)
    assert result.exit_code == 2 and result.stderr.count("\n") == 1, result.output + result.stderr
    assert not out.exists()
    return result.stderr


def test_a_key_that_names_a_matrix_is_refused_naming_its_numbers(tmp_path):
    message = _refused(tmp_path, CV, "--set", "filter.m0=1,4")
    assert "sweep: filter.m0: names the 2 x 2 matrix m0, not one number: sweep one of its numbers, filter.m0.1, filter.m0.2" in message
    assert "truth.phi.1.1, truth.phi.1.2, truth.phi.2.1, truth.phi.2.2" in _refused(tmp_path, CV, "--set", "truth.phi=1,2")


def test_the_timing_over_a_log_the_sample_period_and_what_is_no_number_are_refused(tmp_path):
    log = _cv_log(tmp_path / "log.csv")
    for key in ("model.updates=5,10", "filter.steps_per_update=5,10", "filter.sample_period=0.1,0.2"):
        assert "the log sets the run's timing" in _refused(tmp_path, CV_LOG, "--data", log, "--set", key)
    assert "only relabels the update times" in _refused(tmp_path, CV, "--set", "filter.sample_period=0.1,0.2")
    assert "not a number of the model" in _refused(tmp_path, CV, "--set", "model.name=a,b")
    assert "filter.q: expected a model file's setting" in _refused(tmp_path, CV, "--set", "filter.q=1,2")
    assert "the file has no b (no known inputs)" in _refused(tmp_path, CV, "--set", "filter.b=1,2")


def test_a_diffuse_filter_is_swept_as_verify_takes_it(tmp_path):
    # without a [truth] m0 refused in verify's words; with one, each value's run is that verify's
    diffuse = CV.replace("m0    = [[25.0, 3.0], [3.0, 1.0]]", 'm0 = [[0.0, 0.0], [0.0, 1.0]]\ndiffuse = ["x1"]')
    message = _refused(tmp_path, diffuse, "--set", "filter.v=1,4")
    assert "starts diffuse in x1 and it has no [truth] m0: give [truth] m0" in message
    model = tmp_path / "diffuse.toml"
    model.write_text(diffuse + "\n[truth]\nm0 = [[25.0, 3.0], [3.0, 1.0]]\n")
    result = kalcal.sweep(model, "filter.v", [1, 4], n=200, seed=5, out=tmp_path / "sw")
    for value, run in zip(result.values, result.runs):
        alone = tmp_path / f"alone{value}"
        kalcal.verify(model, 200, seed=5, settings={"filter.v": value}, out=alone)
        numbers = _numbers(run / "summary.json")
        assert numbers == _numbers(alone / "summary.json") and "the diffuse period" in json.dumps(numbers)


def test_a_value_whose_gains_refuse_it_is_named_before_the_first_run(tmp_path):
    # a local level started diffuse: with h = 0 the level is never measured, so its diffuse period never
    # ends; the sweep finds it from the value's problem before it runs the first value
    level = """
name = "ll"
sample_period = 1.0
steps_per_update = 1
updates = 40
phi = [[1.0]]
gamma = [[1.0]]
h = [[1.0]]
w = [[0.1]]
v = [[1.0]]
x0 = [0.0]
m0 = [[0.0]]
diffuse = ["level"]
state_names = ["level"]
[truth]
m0 = [[4.0]]
"""
    message = _refused(tmp_path, level, "--set", "filter.h=1,0")  # nothing ran, nothing written (_refused)
    assert "sweep: filter.h=0: " in message and "diffuse period" in message, message
