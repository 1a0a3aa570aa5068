"""``verify``/``analyze`` of a model file whose filter starts diffuse (:mod:`kalcal.scenarios.model_file.diffuse`).

The gains computed once are the exact diffuse filter's (:func:`kalcal.core.timevarying_filter.reference_filter`
run on random data, 1e-12); after the diffuse period the exact error covariance is the filter's P (1e-10)
whatever the world's prior; verify passes at a fixed seed and fails the covariance check when the world's
noise std is 1.5x the filter's (the exact analysis's power at N, from theory, says it must); a diffuse
period that takes the whole run is refused in one line; the same over a log's rows (``--data LOG``).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from kalcal.analysis.fixed_gain import analyze_scenario
from kalcal.core.timevarying import TimeVaryingModel
from kalcal.core.timevarying_filter import reference_filter
from kalcal.scenarios.model_file.diffuse import CheckedWindowProblem
from kalcal.scenarios.model_file.model import parse_model
from kalcal.scenarios.model_file.over_log import over_log
from tests._helpers import invoke as _invoke

#: a local level (a random walk seen in noise), started diffuse; the world's prior proper
LOCAL_LEVEL = """
name = "local-level"
steps_per_update = 1
updates = 40
phi = [[1.0]]
gamma = [[1.0]]
h = [[1.0]]
w = [[0.5]]
v = [[2.0]]
x0 = [0.0]
m0 = [[0.0]]
diffuse = ["level"]
state_names = ["level"]

[truth]
m0 = [[100.0]]
x0 = [3.0]
"""
#: a local linear trend, both states diffuse, two model steps between updates
TREND = """
name = "local-linear-trend"
steps_per_update = 2
updates = 30
phi = [[1.0, 1.0], [0.0, 1.0]]
gamma = [[1.0, 0.0], [0.0, 1.0]]
h = [[1.0, 0.0]]
w = [[0.3, 0.0], [0.0, 0.01]]
v = [[1.5]]
x0 = [5.0, 0.0]
m0 = [[0.0, 0.0], [0.0, 0.0]]
diffuse = ["level", "slope"]
state_names = ["level", "slope"]

[truth]
m0 = [[50.0, 1.0], [1.0, 4.0]]
x0 = [1.0, -2.0]
"""
#: seed 003's regression with both states diffuse: y_k = s z_k + b + v_k, the row h_k = [z_k, 1] from a log
REGRESSION = """
name = "regression"
sample_period = 0.01
phi   = [[1.0, 0.0], [0.0, 1.0]]
gamma = [[1.0, 0.0], [0.0, 1.0]]
h     = [["sensor", 1.0]]
w     = [[1e-6, 0.0], [0.0, 1e-6]]
v     = [[0.01]]
x0    = [0.0, 0.0]
m0    = [[0.0, 0.0], [0.0, 0.0]]
diffuse = ["scale", "bias"]
state_names = ["scale", "bias"]
[truth]
x0    = [1.0, 0.0]
m0    = [[0.04, 0.0], [0.0, 0.25]]
[data]
time = "t"
measurements = ["y"]
"""


def _time_varying(scenario) -> tuple[TimeVaryingModel, np.ndarray]:
    """The file's filter as the log filter's model: row 0 the prior, update k at row k * steps_per_update."""
    f, updates = scenario.filter, scenario.model.updates
    m, d, p = f.steps_per_update, f.state_dim, f.measurement_dim
    rows = np.arange(1, updates + 1) * m
    count = updates * m + 1
    diffuse = np.array([n in f.diffuse for n in scenario.model.state_names])
    model = TimeVaryingModel(
        phi=f.phi, gamma=f.gamma, w=f.w, b=None, x0=f.x0, m0=f.m0, h=np.broadcast_to(f.h, (count, p, d)).copy(),
        v=np.broadcast_to(f.v, (count, p, p)).copy(), u=np.zeros((count, 0)), diffuse=diffuse, sample_period=1.0,
        times=np.arange(count, dtype=float),
    )  # fmt: skip
    return model, rows


def _reference_estimates(model: TimeVaryingModel, rows: np.ndarray, z: np.ndarray) -> np.ndarray:
    """The exact diffuse filter's estimates at the update rows (NaN where a state is not yet determined)."""
    full = np.full((model.steps, z.shape[1]), np.nan)
    full[rows] = z
    return reference_filter(model, full).state[rows]


def _gains_against_reference(problem, model, rows, first):
    """The problem's estimates on random data equal the reference's wherever it has one, and its gains K_k
    (d x_k / d z_k, by a unit change of z_k: the filter is linear) from the diffuse period's last update on."""
    rng = np.random.default_rng(7)
    full = problem.full
    p = full.filter_model.measurement_dim
    for _ in range(3):  # any data
        z = rng.normal(0.0, 5.0, (rows.size, p))
        ours = full.filter(z[None]).posterior[0]
        theirs = _reference_estimates(model, rows, z)
        known = np.isfinite(theirs)
        assert known[first - 1:].all()  # proper from the diffuse period's last update on
        assert first == 1 or not known[0].all()  # and not before it
        np.testing.assert_allclose(ours[known], theirs[known], rtol=0.0, atol=1e-12 * max(1.0, np.max(np.abs(theirs[known]))))
    z = rng.normal(0.0, 1.0, (rows.size, p))
    base = _reference_estimates(model, rows, z)
    for k in range(first - 1, rows.size):
        for i in range(p):
            moved = z.copy()
            moved[k, i] += 1.0
            gain = _reference_estimates(model, rows, moved)[k] - base[k]
            np.testing.assert_allclose(full.schedule.gain[k][:, i], gain, rtol=0.0, atol=1e-12)
    # and the filter's P after the period is the exact filter's
    reference_cov = reference_filter(model, np.where(np.isin(np.arange(model.steps), rows)[:, None], 0.0, np.nan)).cov[rows]
    np.testing.assert_allclose(problem.schedule.posterior_cov, reference_cov[first:], rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize(("text", "first"), [(LOCAL_LEVEL, 1), (TREND, 2)])
def test_the_gains_are_the_exact_diffuse_filters(text, first):
    scenario = parse_model(text, "model.toml")
    problem = scenario.problem()
    assert isinstance(problem, CheckedWindowProblem) and problem.first == first  # one diffuse state a measurement
    model, rows = _time_varying(scenario)
    _gains_against_reference(problem, model, rows, first)
    assert problem.info.update_times.size == scenario.model.updates - first
    for form in ("standard", "sqrt"):  # the ordinary pass after the period in the run's form: the same P
        other = scenario.problem(form)
        np.testing.assert_allclose(other.schedule.posterior_cov, problem.schedule.posterior_cov, rtol=1e-10, atol=1e-14)
        np.testing.assert_allclose(other.full.schedule.gain, problem.full.schedule.gain, rtol=1e-10, atol=1e-14)
    assert problem.info.not_checked == ("the diffuse period, update 1" if first == 1 else "the diffuse period, updates 1..2")


def test_a_diffuse_state_that_the_transition_forgets_leaves_nothing_out():
    # x2 is diffuse but phi maps it to 0 before the first update: every update is checked, with the
    # exact diffuse filter's P
    text = TREND.replace("phi = [[1.0, 1.0], [0.0, 1.0]]", "phi = [[1.0, 0.0], [0.0, 0.0]]").replace(
        'm0 = [[0.0, 0.0], [0.0, 0.0]]\ndiffuse = ["level", "slope"]', 'm0 = [[4.0, 0.0], [0.0, 0.0]]\ndiffuse = ["slope"]'
    )
    scenario = parse_model(text, "model.toml")
    problem = scenario.problem()
    assert not isinstance(problem, CheckedWindowProblem) and problem.first == 0 and problem.info.not_checked == ""
    model, rows = _time_varying(scenario)
    reference = reference_filter(model, np.where(np.isin(np.arange(model.steps), rows)[:, None], 0.0, np.nan))
    np.testing.assert_allclose(problem.schedule.posterior_cov, reference.cov[rows], rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("text", [LOCAL_LEVEL, TREND])
def test_after_the_diffuse_period_the_exact_error_covariance_is_the_filters_whatever_the_worlds_prior(text):
    d = 1 if text is LOCAL_LEVEL else 2
    analyses = []
    for m0, x0 in (("[[100.0]]", "[3.0]"), ("[[0.25]]", "[-40.0]")) if d == 1 else (
        ("[[50.0, 1.0], [1.0, 4.0]]", "[1.0, -2.0]"), ("[[0.5, 0.0], [0.0, 900.0]]", "[300.0, 7.0]")
    ):  # fmt: skip
        scenario = parse_model(text, "model.toml", [f"truth.m0={m0}", f"truth.x0={x0}"])
        a = analyze_scenario(scenario)
        np.testing.assert_allclose(a.moments.error_cov, a.filter_cov, rtol=0.0, atol=1e-10)
        np.testing.assert_allclose(a.moments.mean_error, 0.0, atol=1e-10)
        np.testing.assert_allclose(a.mean_nees, d, rtol=1e-10)
        np.testing.assert_allclose(a.mean_nis, 1.0, rtol=1e-10)
        analyses.append(a)
    one, two = analyses
    np.testing.assert_allclose(one.moments.error_cov, two.moments.error_cov, rtol=0.0, atol=1e-10)
    # orthogonality does not hold (why it is left out): E[e xhat^T] = Cov(e, xhat) is not zero, and it does not
    # depend on the world's prior either (the mean error is zero, so the means do not enter it)
    np.testing.assert_allclose(one.moments.error_estimate, two.moments.error_estimate, rtol=0.0, atol=1e-9)
    assert np.max(np.abs(one.moments.error_estimate)) > 0.1


def _verify(tmp_path: Path, text: str, name: str, *sets: str, n: int = 2000, data: Path | None = None) -> dict:
    model = tmp_path / f"{name}.toml"
    model.write_text(text)
    args = ["verify", model, "-n", n, "--seed", 11, "--out", tmp_path / name]
    if data is not None:
        args += ["--data", data]
    for item in sets:
        args += ["--set", item]
    result = _invoke(*args)
    assert result.exit_code == 0, result.output
    assert "not checked: the diffuse period" in result.output
    return json.loads((tmp_path / name / "summary.json").read_text())


def test_verify_passes_and_fails_the_covariance_check_when_the_worlds_noise_is_1_5x(tmp_path):
    good = _verify(tmp_path, TREND, "good")
    assert good["verdict"] == "pass" and good["not_checked"] == "the diffuse period, updates 1..2"
    assert [t["name"] for t in good["tests"]] == ["mean_error", "covariance", "residual_whiteness", "nis", "shape"]
    assert "orthogonality" in good["checks_left_out"]
    assert good["final"]["time"] == 60.0
    page = (tmp_path / "good" / "report.html").read_text()
    assert "Not checked: the diffuse period, updates 1..2." in page and "<code>orthogonality</code> left out" in page
    # the world's process and measurement noise std 1.5x the filter's (variances 2.25x): the exact analysis
    # gives the covariance check's power at N = 2000; theory, not this seed, says it detects it
    bad = _verify(tmp_path, TREND, "bad", "truth.w=[[0.675, 0.0], [0.0, 0.0225]]", "truth.v=[[3.375]]")
    power = {row["name"]: row for row in bad["power"] if row["part"] is None}
    assert power["covariance"]["power_low"] >= 0.999
    covariance = next(t for t in bad["tests"] if t["name"] == "covariance")
    assert not covariance["passed"] and bad["verdict"] == "fail"


def test_a_diffuse_period_that_takes_the_whole_run_is_refused_in_one_line(tmp_path):
    never = TREND.replace('h = [[1.0, 0.0]]', 'h = [[0.0, 1.0]]')  # the slope alone is seen: the level never
    short = TREND.replace("updates = 30", "updates = 2")  # the slope is determined at the last update
    for name, text in (("never", never), ("short", short)):
        model = tmp_path / f"{name}.toml"
        model.write_text(text)
        updates = 2 if name == "short" else 30
        for command in (["verify", "-n", 100, "--out", tmp_path / "out"], ["analyze", "--out", tmp_path / "analysis"]):
            result = _invoke(command[0], model, *command[1:])
            assert result.exit_code == 2, result.output
            lines = result.stderr.strip().splitlines()
            assert len(lines) == 1, result.stderr
            assert f"its filter starts diffuse in level, slope and its diffuse period takes all {updates} updates" in lines[0]
            assert lines[0].startswith(f"{model}:") or str(model) in lines[0]
        assert not (tmp_path / "out").exists()


def _regression_log(path: Path, count: int = 400) -> Path:
    rng = np.random.default_rng(3)
    sensor = 2.0 + np.cumsum(rng.normal(0.0, 0.3, count))  # a wandering regressor: the rows change
    y = np.where(np.arange(count) % 4 == 3, 1.0, np.nan)  # a fix every 4th row, the first at row 3
    pd.DataFrame({"t": np.arange(count) * 0.01, "sensor": sensor, "y": y}).to_csv(path, index=False)
    return path


def test_verify_over_a_logs_rows_with_a_diffuse_filter(tmp_path):
    log = _regression_log(tmp_path / "log.csv")
    scenario = over_log(parse_model(REGRESSION, "regression.toml"), log)
    problem = scenario.problem()
    # the regression's two states are determined by two rows whose regressors differ
    assert isinstance(problem, CheckedWindowProblem) and problem.first == 2
    bound = scenario.bound
    rows = scenario.arrays.rows
    _gains_against_reference(problem, bound.filter, rows, 2)
    a = analyze_scenario(scenario)
    np.testing.assert_allclose(a.moments.error_cov, a.filter_cov, rtol=1e-10, atol=1e-14)
    summary = _verify(tmp_path, REGRESSION, "logged", data=log)
    assert summary["verdict"] == "pass" and summary["not_checked"] == "the diffuse period, updates 1..2"
    assert summary["realizations"] == 2000 and "orthogonality" not in [t["name"] for t in summary["tests"]]
    # the report rebuilds the run from its summary (the log read again from its recorded path)
    rebuilt = _invoke("report", tmp_path / "logged")
    assert rebuilt.exit_code == 0, rebuilt.output
    assert "Not checked: the diffuse period, updates 1..2." in (tmp_path / "logged" / "report.html").read_text()
    # analyze --data says the same
    model = tmp_path / "logged.toml"
    result = _invoke("analyze", model, "--data", log, "--out", tmp_path / "analysis")
    assert result.exit_code == 0, result.output
    assert "not checked: the diffuse period, updates 1..2" in result.output
    document = json.loads((tmp_path / "analysis" / "analysis.json").read_text())
    assert document["not_checked"] == "the diffuse period, updates 1..2"
    assert "orthogonality" in document["checks_left_out"]
    assert "orthogonality" not in {row["name"] for row in document["power"]}
