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

from kalcal.montecarlo.accumulators import MomentSums
from kalcal.scenarios.model_file.model import parse_model
from kalcal.scenarios.model_file.over_log import over_log
from tests._helpers import invoke as _invoke

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


#: the sums that hold the estimate (the filter's response to the inputs enters them), the rest free of u
_ESTIMATE_SUMS = ("estimate", "estimate_outer", "error_estimate", "whitened_estimate")


def test_the_errors_do_not_depend_on_u_where_the_truths_b_is_the_filters(tmp_path):
    text = CV_LOG.replace("[data]", 'b = [[0.005], [0.1]]\n[data]\ninputs = ["a"]')
    scenario = parse_model(text, "cv.toml")
    rng = np.random.default_rng(0)
    driven = over_log(scenario, _cv_log(tmp_path / "driven.csv", a=rng.normal(0.0, 5.0, 301))).problem()
    still = over_log(scenario, _cv_log(tmp_path / "still.csv", a=np.zeros(301))).problem()
    a, b = _sums(driven, 2, 300), _sums(still, 2, 300)
    for name in (f.name for f in dataclasses.fields(MomentSums) if f.name not in _ESTIMATE_SUMS):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name  # bit for bit
    # the estimates are the filter's with its inputs: shifted by its own response f_k, n f_k in the sum
    f = driven.truth.estimate_offset
    assert f is not None and np.any(f) and not np.any(still.truth.estimate_offset)
    np.testing.assert_allclose(a.estimate, b.estimate + 300 * f, rtol=1e-12, atol=1e-9)


# Where the truth's prior mean is not the filter's, the mean error is not zero and E[e xhat^T] depends on u:
# the run whose inputs cancel must give the orthogonality sums of the same file run with its inputs carried
# as truth states (driven_truth), which holds the filter's estimates with its inputs by construction.
def test_the_orthogonality_sums_hold_the_inputs_where_the_mean_error_is_not_zero(tmp_path, monkeypatch):
    from kalcal.scenarios.model_file import model as model_module

    text = DRIVEN.replace("x0    = [0.0, 10.0]", "x0    = [0.0, 0.0]") + "\n"
    text = text.replace("[data]", "[truth]\nx0 = [0.0, 0.25]\n\n[data]")
    log = _driven_log(tmp_path / "log.csv")
    cancelled = over_log(parse_model(text, "cv.toml"), log).problem()
    assert cancelled.truth.error_map is None  # the inputs cancel: no input state
    monkeypatch.setattr(model_module, "_inputs_cancel", lambda scenario: False)
    carried = over_log(parse_model(text, "cv.toml"), log).problem()
    assert carried.truth.error_map is not None  # the inputs carried as truth states
    a, b = _sums(cancelled, 5, 400), _sums(carried, 5, 400)
    scale = np.max(np.abs(b.error_estimate))
    np.testing.assert_allclose(a.error_estimate, b.error_estimate, rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(a.estimate, b.estimate, rtol=0, atol=1e-9 * np.max(np.abs(b.estimate)))
    np.testing.assert_allclose(a.error, b.error, rtol=0, atol=1e-9 * np.max(np.abs(b.error)))


@pytest.mark.parametrize(
    ("edit", "columns", "expected"),
    [
        # a diffuse filter is verified over a log (tests/models/test_model_file_diffuse.py) where its [truth]
        # gives the world's m0; without one the world would start exactly at x0 in the diffuse state
        (lambda t: t.replace('m0    = [[25.0, 0.0], [0.0, 1.0]]', 'm0 = [[0.0, 0.0], [0.0, 1.0]]\ndiffuse = ["x1"]'),
         {}, "it has no [truth] m0: give [truth] m0"),
    ],
)
def test_the_stated_limits_are_refused_in_one_line(tmp_path, edit, columns, expected):
    model = tmp_path / "cv.toml"
    model.write_text(edit(CV_LOG))
    log = _cv_log(tmp_path / "log.csv", **columns)
    for command in (["verify", "-n", 300, "--out", tmp_path / "out"], ["analyze", "--out", tmp_path / "analysis"]):
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


# A truth driven by the known input otherwise than the filter believes: the error gets a deterministic
# offset, which the Monte Carlo and the exact analysis over a log both carry.
DRIVEN = CV_LOG.replace("[data]", 'b = [[0.005], [0.1]]\n[data]\ninputs = ["a"]')
TRUTH_B = DRIVEN.replace("[data]", "[truth]\nb = [[0.006], [0.12]]\n\n[data]")  # B_t = 1.2 B
TRUTH_PHI = DRIVEN.replace("[data]", "[truth]\nphi = [[1.0, 0.1], [0.0, 0.98]]\n\n[data]")  # B_t = B, its own phi


def _driven_log(path: Path) -> Path:
    a = 3.0 + np.random.default_rng(4).normal(0.0, 1.0, 301)  # an acceleration that moves the state, m/s^2
    return _cv_log(path, a=a)


# a truth of its own, [position, velocity, bias]: the measurement carries a slowly decaying bias the filter
# does not model, and the input drives the truth's velocity 1.2 times as hard as the filter believes
TRUTH_MAP = DRIVEN.replace("[data]", """[truth]
map = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
phi = [[1.0, 0.1, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.95]]
gamma = [[0.005, 0.0], [0.1, 0.0], [0.0, 0.3]]
w = [[0.04, 0.0], [0.0, 1.0]]
h = [[1.0, 0.0, 1.0]]
v = [[4.0]]
x0 = [0.0, 10.0, 0.5]
m0 = [[25.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
b = [[0.006], [0.12], [0.0]]

[data]""")


def _direct_mean_error(scenario, log: Path) -> np.ndarray:
    """E[e_k] by one recursion over the log's rows, written out: the truth's mean x_{j+1} = Phi_t x_j +
    B_t u_j from x0; the filter's xhat_{j+1}^- = Phi xhat_j + B u_j with its own Riccati gains at each
    measured row, updated by the mean measurement H_t x_j (the noise has mean zero); e = M x - xhat.
    Returns E[e_k] and E[xhat_k], (K, 2) each."""
    f, t = scenario.filter, scenario.truth
    error_map = scenario.truth_map if scenario.truth_map is not None else np.eye(2)
    h_truth = np.nan_to_num(t.h, nan=1.0)  # an h naming the column c, which is 1.0 on every row
    frame = pd.read_csv(log)
    u, measured = frame["a"].to_numpy()[:, None], np.isfinite(frame["z"].to_numpy())
    h = np.array([[1.0, 0.0]])  # the column c is 1.0 on every row
    x, xhat, cov = t.x0.copy(), f.x0.copy(), f.m0.copy()
    out, estimates = [], []
    for j in range(1, len(frame)):
        x = t.phi @ x + t.b @ u[j - 1]
        xhat = f.phi @ xhat + f.b @ u[j - 1]
        cov = f.phi @ cov @ f.phi.T + f.gamma @ f.w @ f.gamma.T
        if measured[j]:
            s = h @ cov @ h.T + f.v
            gain = np.linalg.solve(s, h @ cov).T
            xhat = xhat + gain @ (h_truth @ x - h @ xhat)
            cov = (np.eye(2) - gain @ h) @ cov
            out.append(error_map @ x - xhat)
            estimates.append(xhat)
    return np.array(out), np.array(estimates)


def test_a_truth_b_equal_to_the_filters_gives_the_input_free_error_sums(tmp_path):
    driven = over_log(parse_model(DRIVEN, "cv.toml"), _driven_log(tmp_path / "log.csv")).problem()
    free = over_log(parse_model(CV_LOG, "cv.toml"), _cv_log(tmp_path / "free.csv")).problem()
    assert driven.truth.state_dim == 2 and driven.truth.error_map is None  # the truth carries no input state
    a, b = _sums(driven, 2, 300), _sums(free, 2, 300)
    for name in (f.name for f in dataclasses.fields(MomentSums) if f.name not in _ESTIMATE_SUMS):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name  # bit for bit: the file without b
    assert not np.any(driven.expected_mean_error())


@pytest.mark.parametrize("text", [TRUTH_B, TRUTH_PHI, TRUTH_MAP], ids=["truth-b", "truth-phi", "truth-map"])
def test_a_truth_driven_otherwise_gets_the_exact_mean_offset_in_the_monte_carlo(tmp_path, text):
    from kalcal.analysis.fixed_gain import analyze_problem
    from kalcal.stats.bounds import normal_bound

    log = _driven_log(tmp_path / "log.csv")
    scenario = over_log(parse_model(text, "cv.toml"), log)
    problem = scenario.problem()
    direct, estimate = _direct_mean_error(scenario, log)
    analysis = analyze_problem(problem, scenario.error_sources())
    scale = np.max(np.abs(direct))
    assert scale > 1.0  # the offset matters: metres of position error
    np.testing.assert_allclose(analysis.moments.mean_error, direct, rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(problem.expected_mean_error(), direct, rtol=0, atol=1e-9 * scale)
    # the estimates are the filter's with its inputs (not those less its own response to them)
    np.testing.assert_allclose(analysis.moments.mean_estimate, estimate, rtol=0, atol=1e-9 * np.max(np.abs(estimate)))
    # the budget still sums to P_true: the offset is a mean, not a variance
    total = sum(term.error_cov for term in analysis.budget)
    np.testing.assert_allclose(total, analysis.moments.error_cov, rtol=1e-9, atol=1e-12)
    # the Monte Carlo's mean error at each update against the exact mean: z over K d comparisons
    n = 4000
    sums = _sums(problem, 7, n)
    se = np.sqrt(np.diagonal(analysis.moments.error_cov, axis1=1, axis2=2) / n)
    z = (sums.error / n - direct) / se
    assert np.max(np.abs(z)) < normal_bound(0.999, z.size), np.max(np.abs(z))
    se_estimate = np.sqrt(np.diagonal(analysis.moments.estimate_cov, axis1=1, axis2=2) / n)
    z_estimate = (sums.estimate / n - estimate) / se_estimate
    assert np.max(np.abs(z_estimate)) < normal_bound(0.999, z_estimate.size), np.max(np.abs(z_estimate))
    # and the numpy reference draws the same realizations with the offset, and the same estimates
    block = problem.run_block(np.random.default_rng(7), 64, "exact")
    small = _sums(problem, 7, 64)
    np.testing.assert_allclose(np.einsum("nki->ki", block.error), small.error, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(np.einsum("nki->ki", block.estimate), small.estimate, rtol=1e-9)
    np.testing.assert_allclose(np.einsum("nki,nkj->kij", block.error, block.estimate), small.error_estimate, rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(np.einsum("nki,nkj->kij", block.estimate, block.estimate), small.estimate_outer, rtol=1e-9)
    error, shown = problem.shown_realization(np.random.default_rng(7), 64, 5, "exact")[:2]
    np.testing.assert_allclose(shown, block.estimate[5], rtol=1e-9)
    np.testing.assert_allclose(error, block.error[5], rtol=1e-9, atol=1e-9)


def test_the_mean_error_check_fails_with_a_bias_when_the_truths_b_is_larger(tmp_path):
    import kalcal

    log = _driven_log(tmp_path / "log.csv")
    verdicts = {}
    for label, text in (("equal", DRIVEN), ("larger", TRUTH_B)):
        model = tmp_path / f"{label}.toml"
        model.write_text(text)
        summary = kalcal.verify(model, 2000, seed=3, data=log).raw_summary
        verdicts[label] = {t["name"]: t for t in summary["tests"]}
        assert summary["self_check"]["agrees"], label  # the Monte Carlo against the exact analysis
        # the run says which: the inputs cancel (not read), or the error carries their offset
        said = {"equal": "do not depend on u: the log's inputs enter the estimates alone", "larger": "the truth's b moves it with the known inputs otherwise"}
        assert len(summary["notes"]) == 1 and said[label] in summary["notes"][0], summary["notes"]
    assert all(t["passed"] for t in verdicts["equal"].values()), [n for n, t in verdicts["equal"].items() if not t["passed"]]
    biased = verdicts["larger"]["mean_error"]
    assert not biased["passed"]
    assert biased["statistic"] > 10 * biased["upper"], biased  # a clear bias, not a marginal one
    # and it is the offset the exact analysis predicts: removing it leaves the deviations inside the bound
    assert biased["cause"]["explained_by"] == "model_error", biased["cause"]
    assert "the truth's b differing from the filter's (the known inputs u move the truth" in biased["cause"]["reason"]
    # the size the docs state: the exact offset peaks at about 30 filter sigma (velocity, near the end)
    problem = over_log(parse_model(TRUTH_B, "cv.toml"), log).problem()
    sigma = np.sqrt(np.diagonal(problem.schedule.posterior_cov, axis1=1, axis2=2))
    assert 29.0 < np.max(np.abs(problem.expected_mean_error()) / sigma) < 31.0


@pytest.mark.parametrize(("text", "expected"), [
    (TRUTH_B, "its truth's inputs (b) differ from the filter's, so the filter's error depends on the inputs u"),
    (TRUTH_PHI, "its truth's phi differs from the filter's beside known inputs"),
], ids=["truth-b", "truth-phi"])
def test_without_a_log_a_truth_driven_otherwise_is_refused_in_one_line(tmp_path, text, expected):
    model = tmp_path / "cv.toml"
    model.write_text(text.replace('h     = [["c", 0.0]]', 'h     = [[1.0, 0.0]]'))  # no row from data
    for command in (["verify", "-n", 300, "--out", tmp_path / "out"], ["analyze", "--out", tmp_path / "analysis"]):
        result = _invoke(command[0], model, *command[1:])
        assert result.exit_code == 2, result.output
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and expected in lines[0] and "--data LOG" in lines[0], result.stderr


def test_verify_and_analyze_say_what_the_known_inputs_do_and_a_file_without_them_says_nothing(tmp_path):
    log = _driven_log(tmp_path / "log.csv")
    for text, said in ((DRIVEN, "note: the known inputs u move the truth and the filter's prediction alike"),
                       (TRUTH_B, "note: the truth's b moves it with the known inputs otherwise than the filter")):
        model = tmp_path / "cv.toml"
        model.write_text(text)
        for command in (["verify", "-n", 200, "--out", tmp_path / "out"], ["analyze", "--out", tmp_path / "analysis"]):
            result = _invoke(command[0], model, "--data", log, *command[1:])
            assert result.exit_code == 0, result.output + result.stderr
            assert said in " ".join(result.output.split()), result.output
        # and in the files: summary.json's and analysis.json's notes, the report below its checks
        written = said.removeprefix("note: ")
        assert written in json.loads((tmp_path / "analysis" / "analysis.json").read_text())["notes"][0]
        assert written in json.loads((tmp_path / "out" / "summary.json").read_text())["notes"][0]
        import html

        report = html.unescape(" ".join((tmp_path / "out" / "report.html").read_text().split()))
        assert "<p>Note: " + written in report
    model.write_text(CV_LOG)
    result = _invoke("verify", model, "--data", _cv_log(tmp_path / "plain.csv"), "-n", 200, "--out", tmp_path / "plain")
    assert result.exit_code == 0 and "known inputs" not in result.output
    assert "notes" not in json.loads((tmp_path / "plain" / "summary.json").read_text())
