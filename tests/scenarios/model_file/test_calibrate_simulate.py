"""A model file's calibrate and simulate: the filter's estimates over simulated logs hold their sigmas
(NEES chi-square over seeds, a bound from theory), the simulated log keeps the given log's rows, and the
result's files and keys."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from kalcal.errors import ConfigError, KalcalError
from kalcal.results.calibration import CalibrateOptions
from kalcal.scenarios.model_file.calibrate import ModelFileCalibrationResult, calibrate_model_file, normalized_series
from kalcal.scenarios.model_file.model import parse_model
from kalcal.stats.distributions import chi2_isf

#: a constant-velocity tracker driven by a known acceleration; position measured every 5th row with a std
#: column, velocity every 2nd row (rows measure different components), v correlated
TRACKER = """
name = "tracker"
sample_period = 0.1
phi = [[1.0, 0.1], [0.0, 1.0]]
gamma = [[0.005], [0.1]]
b = [[0.005], [0.1]]
w = [[0.04]]
h = [[1.0, 0.0], [0.0, 1.0]]
v = [[4.0, 0.4], [0.4, 1.0]]
x0 = [0.0, 10.0]
m0 = [[25.0, 0.0], [0.0, 1.0]]
state_names = ["position", "velocity"]
state_units = ["m", "m/s"]
measurement_names = ["pos", "vel"]

[data]
time = "t"
measurements = ["pos", "vel"]
inputs = ["acc"]
stds = ["pos_std", ""]
"""

#: seed 003's form: h_j = [reference_j, 1], both states diffuse in the filter, a proper world prior
DIFFUSE = """
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

[truth]
x0 = [1.02, 0.3]
m0 = [[0.0004, 0.0], [0.0, 0.01]]

[data]
time = "t"
measurements = ["sensor"]
"""


def tracker_log(rows: int = 120, seed: int = 1) -> pd.DataFrame:
    """The rows a tracker's log gives: times, the input, the stds and which rows measure what."""
    rng = np.random.default_rng(seed)
    j = np.arange(rows)
    pos = np.where(j % 5 == 0, 0.0, np.nan)
    vel = np.where(j % 2 == 0, 0.0, np.nan)
    return pd.DataFrame({"t": j * 0.1, "pos": pos, "vel": vel, "acc": np.sin(j * 0.1),
                         "pos_std": np.where(np.isfinite(pos), 1.5 + rng.random(rows), np.nan)})  # fmt: skip


def diffuse_log(rows: int = 100) -> pd.DataFrame:
    j = np.arange(rows)
    return pd.DataFrame({"t": j * 0.01, "reference": np.sin(0.3 * j) * 5.0, "sensor": np.zeros(rows)})


def _nees(error: np.ndarray, cov: np.ndarray) -> float:
    lower = np.linalg.cholesky(cov)
    white = np.linalg.solve(lower, error)
    return float(white @ white)


def _nees_over_seeds(text: str, log: pd.DataFrame, seeds: range, row: int, smooth: bool = False) -> tuple[float, int]:
    """sum over seeds of the NEES of the true states at ``row`` against the filter's (or smoother's) P, and
    its chi-square degrees of freedom (d per seed: the seeds' errors are independent)."""
    scenario = parse_model(text, "model.toml")
    names = scenario.model.state_names
    total = 0.0
    for seed in seeds:
        simulated = scenario.simulate(seed, {"data": log}).logs["data"]
        result = calibrate_model_file(scenario, simulated, smooth=smooth, windows=1)
        truth = simulated[[f"{n}_true" for n in names]].to_numpy()[row]
        if smooth:
            state, cov = result.smoothed.state[row], result.smoothed.cov[row]
        else:
            state, cov = result.run.state[row], result.run.cov[row]
        total += _nees(truth - state, cov)
    return total, len(seeds) * len(names)


#: each NEES test's two-sided false-alarm rate: 1e-3 (a consistent filter fails one in a thousand seeds sets)
ALPHA = 1e-3


def _assert_chi2(total: float, dof: int) -> None:
    lower, upper = chi2_isf(1 - ALPHA / 2, dof), chi2_isf(ALPHA / 2, dof)
    assert lower <= total <= upper, f"NEES sum {total:.4g} on {dof} dof outside [{lower:.4g}, {upper:.4g}] at {ALPHA}"


@pytest.mark.parametrize("text,log,row", [(TRACKER, tracker_log(), -1), (TRACKER, tracker_log(), 37), (DIFFUSE, diffuse_log(), -1)],
                         ids=["tracker-final", "tracker-row-37", "diffuse-final"])
def test_the_filter_on_simulated_logs_holds_its_covariance(text, log, row):
    # NEES of the true states against P summed over 40 independent seeds is chi-square(40 d) for a filter
    # whose model is the world's (and for a diffuse start: its error is N(0, P) for any true value)
    _assert_chi2(*_nees_over_seeds(text, log, range(40), row))


def test_the_smoother_on_simulated_logs_holds_its_covariance():
    _assert_chi2(*_nees_over_seeds(TRACKER, tracker_log(), range(40), 30, smooth=True))


@pytest.mark.slow
@pytest.mark.parametrize("text,log", [(TRACKER, tracker_log(2000)), (DIFFUSE, diffuse_log(2000))], ids=["tracker", "diffuse"])
def test_the_filter_holds_its_covariance_over_long_logs_and_many_seeds(text, log):
    _assert_chi2(*_nees_over_seeds(text, log, range(400), -1))
    _assert_chi2(*_nees_over_seeds(text, log, range(400, 800), 1000, smooth=True))


def test_a_wrong_noise_setting_fails_the_same_nees_test():
    # the test has power: a filter that believes v 25x smaller than the world's is rejected
    wrong = TRACKER.replace("[data]", "[truth]\nv = [[100.0, 10.0], [10.0, 25.0]]\n\n[data]")
    total, dof = _nees_over_seeds(wrong, tracker_log(), range(40), -1)
    assert total > chi2_isf(ALPHA / 2, dof)


def test_simulate_keeps_the_given_rows_and_draws_from_the_seed_alone():
    scenario = parse_model(TRACKER, "model.toml")
    log = tracker_log()
    first = scenario.simulate(7, {"data": log}).logs["data"]
    assert list(first.columns) == ["t", "pos", "vel", "acc", "pos_std", "position_true", "velocity_true"]
    for column in ("t", "acc", "pos_std"):  # copied as given (NaN where given NaN)
        np.testing.assert_array_equal(first[column].to_numpy(), log[column].to_numpy())
    for column in ("pos", "vel"):  # the same missing pattern, drawn values elsewhere
        np.testing.assert_array_equal(np.isnan(first[column]), np.isnan(log[column]))
        assert np.all(first[column].dropna() != 0.0)
    pd.testing.assert_frame_equal(first, scenario.simulate(7, {"data": log}).logs["data"])
    assert not np.allclose(first["pos"].dropna(), scenario.simulate(8, {"data": log}).logs["data"]["pos"].dropna())
    # the truth follows x_{j+1} = Phi x_j + B u_j + Gamma w_j: the position's step is 0.1 v + 0.005 (u + w)
    # and the velocity's 0.1 (u + w), so pos_{j+1} - pos_j - 0.1 vel_j = 0.05 (vel_{j+1} - vel_j) exactly
    p, v = first["position_true"].to_numpy(), first["velocity_true"].to_numpy()
    np.testing.assert_allclose(np.diff(p) - 0.1 * v[:-1], 0.05 * np.diff(v), atol=1e-12)


def test_a_data_column_of_h_is_copied_and_a_diffuse_filter_needs_a_truth_m0():
    scenario = parse_model(DIFFUSE, "model.toml")
    simulated = scenario.simulate(1, {"data": diffuse_log()}).logs["data"]
    assert list(simulated.columns) == ["t", "sensor", "reference", "scale_true", "bias_true"]
    np.testing.assert_array_equal(simulated["reference"], diffuse_log()["reference"])
    no_truth = DIFFUSE.replace("[truth]\nx0 = [1.02, 0.3]\nm0 = [[0.0004, 0.0], [0.0, 0.01]]\n", "")
    with pytest.raises(ConfigError, match=r"^model.toml: its filter starts diffuse in scale, bias and it has no \[truth\] m0"):
        parse_model(no_truth, "model.toml").simulate(1, {"data": diffuse_log()})


def test_simulate_and_calibrate_need_the_data_log():
    scenario = parse_model(TRACKER, "model.toml")
    with pytest.raises(KalcalError, match=r"^--data: required to simulate a model file \(model.toml\)"):
        scenario.simulate(1)
    with pytest.raises(KalcalError, match=r"^--data: required to calibrate a model file \(model.toml\)"):
        scenario.calibrate({"data": None}, CalibrateOptions())


def test_the_built_ins_refuse_a_log_to_simulate():
    from kalcal.scenarios import build_scenario

    with pytest.raises(ConfigError, match=r"^--data: not used by simulate scale-bias \(it draws its own logs\)$"):
        build_scenario("scale-bias").simulate(1, {"data": tracker_log()})


@pytest.mark.parametrize("option,value,owner", [("gate", 0.99, "accel-gps"), ("init", "prior", "accel-gps"),
                                                ("sensor", "s", "scale-bias"), ("prior", "diffuse", "scale-bias")])
def test_options_a_model_file_does_not_take_are_refused_naming_who_does(option, value, owner):
    scenario = parse_model(TRACKER, "model.toml")
    flag = "--" + option.replace("_", "-")
    with pytest.raises(KalcalError, match=rf"^{flag}: not available for a model file \(model.toml\) \({owner} only\)$"):
        scenario.calibrate({"data": tracker_log()}, CalibrateOptions(**{option: value}))


def test_the_result_is_typed_and_its_intervals_are_the_final_states():
    scenario = parse_model(TRACKER, "model.toml")
    log = scenario.simulate(3, {"data": tracker_log(300)}).logs["data"]
    result = scenario.calibrate({"data": log}, CalibrateOptions(smooth=True))
    assert isinstance(result, ModelFileCalibrationResult)
    np.testing.assert_array_equal(result.estimate, result.run.state[-1])
    np.testing.assert_allclose(result.estimate_std, np.sqrt(np.diag(result.run.cov[-1])), rtol=1e-15)
    ci = result.conf_int(level=0.95)
    assert list(ci.index) == ["position", "velocity"]
    np.testing.assert_allclose(ci["upper"] - ci["lower"], 2 * 1.959963984540054 * result.estimate_std, rtol=1e-12)
    summary = result.to_dict()
    for key in ("scenario", "settings", "data", "estimate", "std", "covariance", "loglik", "diffuse_term",
                "loglik_convention", "diagnostics", "stability", "warnings", "units", "proper_from"):
        assert key in summary, key
    assert set(summary["settings"]) == {"model", "filter", "truth", "data"}
    assert summary["loglik"] == pytest.approx(result.run.loglik, rel=0, abs=0) and summary["diffuse_term"] == 0.0
    # rows measure different components: the diagnostics pool the decorrelated components into one series
    assert summary["diagnostics"]["fixes"] == int(np.count_nonzero(np.isfinite(log["pos"])) + np.count_nonzero(np.isfinite(log["vel"])))
    assert summary["stability"]["p_value"] is not None
    assert "position" in result._repr_html_() and "loglik=" in repr(result)


def test_a_diffuse_file_reports_nan_before_its_diffuse_period_ends_and_the_diffuse_term():
    scenario = parse_model(DIFFUSE, "model.toml")
    log = scenario.simulate(2, {"data": diffuse_log()}).logs["data"]
    result = calibrate_model_file(scenario, log, smooth=True)
    run = result.run
    assert run.proper_from == 1  # two components of two rows resolve the two diffuse states
    estimates = result.estimates
    # row 0's reference is 0, so its measurement sees the bias alone: the bias is determined there, the
    # scale (still diffuse) has no finite estimate or sigma, and the row's NIS is not defined (its prior is not proper)
    assert estimates.loc[0, ["scale", "scale_std", "nis", "scale_smoothed", "bias_smoothed"]].isna().all()
    assert np.isfinite(estimates.loc[0, "bias"]) and np.isfinite(estimates.loc[0, "bias_std"])
    assert estimates.loc[1:, ["scale", "bias", "scale_std", "scale_smoothed"]].notna().all().all()
    summary = result.to_dict()
    assert summary["proper_from"] == {"row": 1, "time": 0.01}
    assert summary["diffuse_term"] == run.diffuse_term != 0.0 and summary["conditioned"] == 2
    assert summary["diagnostics"]["fixes"] == len(log) - 2 and summary["diagnostics"]["series"] == ["z1"]  # the default measurement name


def test_normalized_series_is_each_rows_cholesky_whitened_innovation():
    scenario = parse_model(TRACKER, "model.toml")
    log = scenario.simulate(5, {"data": tracker_log(40)}).logs["data"]
    run = calibrate_model_file(scenario, log, windows=1).run
    series, labels, rows = normalized_series(run, ("pos", "vel"))
    expected = []
    for j in rows:
        o = np.flatnonzero(run.measured[j])
        lower = np.linalg.cholesky(run.innovation_cov[j][np.ix_(o, o)])
        expected.extend(np.linalg.solve(lower, run.residual[j, o]))
    np.testing.assert_allclose(series[:, 0], expected, rtol=1e-12)
    np.testing.assert_allclose(np.sum(series[:, 0] ** 2), np.nansum(run.nis), rtol=1e-10)  # the NIS is its square
