"""``verify``/``analyze MODEL.toml --data LOG``: the gains from a log's rows, computed once.

A log of constant rows gives the time-invariant verification's numbers (1e-10); rows that change
(h_k = [z_k, 1], z from a CSV) pass every check and the exact analysis's self-check at a fixed seed; the
inputs are not read where the truth's b is the filter's; the stated limits are refused in one line.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from kalcal.cli import app
from kalcal.montecarlo.accumulators import MomentSums
from kalcal.scenarios.model_file.model import parse_model
from kalcal.scenarios.model_file.over_log import over_log

CV = """
name = "cv"
sample_period = 0.1
steps_per_update = 10
updates = 30
phi   = [[1.0, 0.1], [0.0, 1.0]]
gamma = [[0.005], [0.1]]
h     = [[1.0, 0.0]]
w     = [[0.04]]
v     = [[4.0]]
x0    = [0.0, 10.0]
m0    = [[25.0, 0.0], [0.0, 1.0]]
"""
# the same model whose h takes its first entry from a column c that equals the file's 1.0
CV_LOG = CV.replace('h     = [[1.0, 0.0]]', 'h     = [["c", 0.0]]') + '\n[data]\nmeasurements = ["z"]\n'
# seed 003's regression: y_k = s z_k + b + v_k, the row h_k = [z_k, 1] read from the log
REGRESSION = """
name = "regression"
sample_period = 0.01
phi   = [[1.0, 0.0], [0.0, 1.0]]
gamma = [[1.0, 0.0], [0.0, 1.0]]
h     = [["sensor", 1.0]]
w     = [[1e-6, 0.0], [0.0, 1e-6]]
v     = [[0.01]]
x0    = [1.0, 0.0]
m0    = [[0.04, 0.0], [0.0, 0.25]]
state_names = ["scale", "bias"]
[data]
time = "t"
measurements = ["y"]
"""


def _invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)


def _cv_log(path: Path, count: int = 301, every: int = 10, **columns) -> Path:
    z = np.full(count, np.nan)
    z[every::every] = 0.0  # the values are never read: only which rows are measured
    pd.DataFrame({"z": z, "c": np.ones(count), **columns}).to_csv(path, index=False)
    return path


def _regression_log(path: Path, count: int = 400) -> Path:
    rng = np.random.default_rng(3)
    sensor = 2.0 + np.cumsum(rng.normal(0.0, 0.3, count))  # a wandering regressor: the rows change
    y = np.where(np.arange(count) % 4 == 3, 1.0, np.nan)  # a fix every 4th row, the first at row 3
    pd.DataFrame({"t": np.arange(count) * 0.01, "sensor": sensor, "y": y}).to_csv(path, index=False)
    return path


def _sums(problem, seed: int, n: int) -> MomentSums:
    return problem.block_sums(np.random.default_rng(seed), n, "exact")


def test_a_log_of_constant_rows_gives_the_time_invariant_verification(tmp_path):
    plain = parse_model(CV, "cv.toml").problem()
    logged = over_log(parse_model(CV_LOG, "cv.toml"), _cv_log(tmp_path / "log.csv")).problem()
    np.testing.assert_allclose(logged.schedule.gain, plain.schedule.gain, rtol=1e-10, atol=0)
    np.testing.assert_allclose(logged.schedule.posterior_cov, plain.schedule.posterior_cov, rtol=1e-10, atol=0)
    np.testing.assert_allclose(logged.info.update_times, plain.info.update_times, rtol=1e-12)
    a, b = _sums(plain, 5, 700), _sums(logged, 5, 700)
    for name in (f.name for f in dataclasses.fields(MomentSums)):
        x, y = getattr(a, name), getattr(b, name)
        if isinstance(x, np.ndarray) and x.dtype.kind == "f":
            np.testing.assert_allclose(y, x, rtol=1e-10, atol=1e-10 * float(np.max(np.abs(x), initial=1.0)), err_msg=name)
        elif isinstance(x, np.ndarray):  # the shape check's histograms: the same counts
            np.testing.assert_array_equal(y, x, err_msg=name)
        else:
            assert x == y, name
    np.testing.assert_allclose(logged.expected_mean_error(), plain.expected_mean_error(), atol=1e-12)


def test_the_compiled_kernel_matches_the_numpy_reference_on_changing_rows(tmp_path):
    problem = over_log(parse_model(REGRESSION, "r.toml"), _regression_log(tmp_path / "r.csv")).problem()
    assert np.ptp(problem.filter_model.h[:, 0, 0]) > 1.0  # the rows do change
    block = problem.run_block(np.random.default_rng(11), 64, "exact")
    for index in (0, 37):
        error, estimate = problem.traced_realization(np.random.default_rng(11), 64, index)
        np.testing.assert_allclose(error, block.error[index], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(estimate, block.estimate[index], rtol=1e-9, atol=1e-12)
    sums = _sums(problem, 11, 64)
    np.testing.assert_allclose(sums.error_outer, np.einsum("nki,nkj->kij", block.error, block.error), rtol=1e-9)


def test_changing_rows_pass_every_check_and_the_exact_analysis_agrees(tmp_path):
    import kalcal

    log = _regression_log(tmp_path / "r.csv")
    model = tmp_path / "r.toml"
    model.write_text(REGRESSION)
    result = kalcal.verify(model, 8192, seed=1, data=log)
    summary = result.raw_summary
    assert summary["verdict"] == "pass", [t["name"] for t in summary["tests"] if not t["passed"]]
    assert summary["self_check"]["agrees"]  # the Monte Carlo against the exact analysis of the same gains
    assert summary["settings"]["log"]["path"] == str(log.resolve())
    analysis = kalcal.analyze(model, data=log)
    true_cov = analysis.analysis.moments.error_cov
    np.testing.assert_allclose(true_cov, analysis.analysis.filter_cov, rtol=1e-9)  # truth = filter: P_true = P
    # the budget's terms sum to P_true with per-update Q_k and R_k
    total = sum(term.error_cov for term in analysis.analysis.budget)
    np.testing.assert_allclose(total, true_cov, rtol=1e-9, atol=1e-15)


def test_the_inputs_are_not_read_where_the_truths_b_is_the_filters(tmp_path):
    text = CV_LOG.replace("[data]", 'b = [[0.005], [0.1]]\n[data]\ninputs = ["a"]')
    scenario = parse_model(text, "cv.toml")
    rng = np.random.default_rng(0)
    driven = over_log(scenario, _cv_log(tmp_path / "driven.csv", a=rng.normal(0.0, 5.0, 301))).problem()
    still = over_log(scenario, _cv_log(tmp_path / "still.csv", a=np.zeros(301))).problem()
    a, b = _sums(driven, 2, 300), _sums(still, 2, 300)
    for name in (f.name for f in dataclasses.fields(MomentSums)):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name  # bit for bit


@pytest.mark.parametrize(
    ("edit", "columns", "expected"),
    [
        (lambda t: t.replace('m0    = [[25.0, 0.0], [0.0, 1.0]]', 'm0 = [[0.0, 0.0], [0.0, 1.0]]\ndiffuse = ["x1"]')
         + '\n[truth]\nm0 = [[25.0, 0.0], [0.0, 1.0]]\n', {}, "no diffuse start"),
        (lambda t: t.replace("[data]", 'b = [[0.005], [0.1]]\n[truth]\nb = [[0.0], [0.1]]\n[data]\ninputs = ["a"]'),
         {"a": np.ones(301)}, "depends on the inputs u"),
    ],
)
def test_the_stated_limits_are_refused_in_one_line(tmp_path, edit, columns, expected):
    model = tmp_path / "cv.toml"
    model.write_text(edit(CV_LOG))
    log = _cv_log(tmp_path / "log.csv", **columns)
    for command in (["verify", "-n", 300, "--out", tmp_path / "out"], ["analyze"]):
        result = _invoke(command[0], model, "--data", log, *command[1:])
        assert result.exit_code == 2, result.output
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and expected in lines[0], result.stderr


def test_a_pattern_that_changes_is_refused_naming_its_row(tmp_path):
    text = CV_LOG.replace('h     = [["c", 0.0]]', 'h     = [["c", 0.0], [0.0, 1.0]]').replace(
        'v     = [[4.0]]', 'v     = [[4.0, 0.0], [0.0, 1.0]]').replace('measurements = ["z"]', 'measurements = ["z", "s"]')
    model = tmp_path / "cv.toml"
    model.write_text(text)
    z = np.full(301, np.nan)
    z[10::10] = 0.0
    s = z.copy()
    s[50] = np.nan  # row 51 of the file (1-based) measures z alone
    log = tmp_path / "log.csv"
    pd.DataFrame({"z": z, "s": s, "c": np.ones(301)}).to_csv(log, index=False)
    result = _invoke("verify", model, "--data", log, "-n", 300, "--out", tmp_path / "out")
    assert result.exit_code == 2
    assert result.stderr.count("\n") == 1 and "row 51 measures (z1)" in result.stderr, result.stderr
    # a constant pattern that leaves s out everywhere is verified on z alone
    pd.DataFrame({"z": z, "s": np.full(301, np.nan), "c": np.ones(301)}).to_csv(log, index=False)
    problem = over_log(parse_model(text, "cv.toml"), log).problem()
    assert problem.info.measurement_names == ("z1",)


def test_data_is_refused_for_a_built_in_scenario(tmp_path):
    result = _invoke("verify", "accel-gps", "--data", _cv_log(tmp_path / "log.csv"), "-n", 300, "--out", tmp_path / "o")
    assert result.exit_code == 2 and result.stderr.count("\n") == 1 and "--data" in result.stderr


def test_the_report_rebuilds_from_the_recorded_log_and_refuses_a_changed_one(tmp_path):
    model = tmp_path / "r.toml"
    model.write_text(REGRESSION)
    log = _regression_log(tmp_path / "r.csv")
    out = tmp_path / "run"
    result = _invoke("verify", model, "--data", log, "-n", 300, "--out", out, "--no-report")
    assert result.exit_code == 0, result.output + result.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["settings"]) == {"model", "filter", "truth", "data", "log"}
    model.unlink()  # the report needs the summary and the log, not the file
    rebuilt = _invoke("report", out)
    assert rebuilt.exit_code == 0, rebuilt.output + rebuilt.stderr
    log.write_text(log.read_text() + "")  # unchanged bytes still rebuild
    _regression_log(log, count=401)
    refused = _invoke("report", out)
    assert refused.exit_code == 2 and "has changed since the run read it" in refused.stderr, refused.stderr
