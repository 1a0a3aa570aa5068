"""Both seeds as model files (examples/accel_gps_seed000.toml, examples/scale_bias_seed003.toml) give the
built-in scenarios' numbers: the filter's estimates, covariances, innovations and log-likelihood at fixed
settings to 1e-9, and the fit's estimates to the search's tolerance.

Each side runs its own code: the built-in's filter (accel-gps: the error state about its integrated
nominal, per-interval transitions composed from the samples; scale-bias: its regression filter and its
information-form diffuse start) and the model file bound to the same simulated log, run by
:func:`kalcal.core.timevarying_filter.filter_model` (one row per sample, the accelerometer as an input).
The two are the same filter in exact arithmetic, so what is left is rounding: 1e-9 absolute (in m, m/s,
m/s^2, their squares, and nats) is above it (the largest difference measured is 4.3e-10, accel-gps's
log-likelihood over 6000 rows) and far below any modelling difference (a different prior, step or skipped
fix moves these numbers by 1e-5 and more, as the conventions' tests below show).

The search's tolerance (:mod:`kalcal.fitting.information`): a fit stops where the Newton step's predicted
gain of log L is below GAIN (1e-3) or the gradient in u = ln(value) is below STATIONARY, so each search's
ln(estimate) lies within sqrt(2 GAIN) of its standard errors of the maximum, and two searches of one
likelihood within 2 sqrt(2 GAIN) se of each other (a variance's ln is twice its std's, and so is its se).
"""

from __future__ import annotations

import importlib.util
import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import kalcal
from kalcal.api._scenario import resolve
from kalcal.core.likelihood import innovation_loglik
from kalcal.core.timevarying_filter import filter_model
from kalcal.fitting.information import GAIN
from kalcal.scenarios.model_file.model import load_model_file

ROOT = Path(__file__).resolve().parents[2]
SEED000 = ROOT / "examples" / "accel_gps_seed000.toml"
SEED003 = ROOT / "examples" / "scale_bias_seed003.toml"
#: rounding's room (module docstring)
EXACT = 1e-9
#: two searches of one likelihood agree within this many standard errors of ln(estimate)
SEARCHES = 2.0 * np.sqrt(2.0 * GAIN)


def _seed_logs():
    spec = importlib.util.spec_from_file_location("seed_logs", ROOT / "examples" / "seed_logs.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


seed_logs = _seed_logs()


@pytest.fixture(scope="module")
def accel_gps():
    """seed 000's simulated logs (kalcal simulate accel-gps --seed 0) and the file's table of them."""
    logs = kalcal.simulate("accel-gps", 0).logs
    imu, gps = logs["imu"], logs["gps"]
    return imu, gps, seed_logs.accel_gps_table(imu, gps)


@pytest.fixture(scope="module")
def scale_bias():
    """seed 003's simulated log (kalcal simulate scale-bias --seed 3), already the file's layout."""
    return seed_logs.scale_bias_table(kalcal.simulate("scale-bias", 3).logs["data"])


def _builtin_log(imu, gps, settings=None, prior="scenario"):
    from kalcal.scenarios.accel_gps.log import prepare_accel_gps_log

    # the built-in as the file can state it: Euler (the default), --init prior, a proper 1000 m/s^2 bias prior
    settings = {"filter.bias_std": 1000.0} if settings is None else settings
    scenario = resolve("accel-gps", settings, None)
    arrays = (imu["time"], imu["accel"], gps["time"], gps["position"], gps["velocity"])
    return scenario, prepare_accel_gps_log(scenario, *(a.to_numpy() for a in arrays), init="prior", prior=prior)


def _file_run(path, table, sets=()):
    bound = load_model_file(path, list(sets)).bind(table)
    return bound, filter_model(bound.filter, bound.z)


# -- the log's layout ---------------------------------------------------------------------------------------------


def test_the_table_puts_each_fix_on_its_sample_and_nan_between(accel_gps):
    imu, gps, table = accel_gps
    assert list(table.columns) == ["time", "accel", "position", "velocity"] and len(table) == len(imu) == 6001
    fixed = np.flatnonzero(np.isfinite(table["position"].to_numpy()))
    np.testing.assert_array_equal(fixed, np.arange(1, 151) * 40)  # 5 Hz on the 200 Hz rows, the first at 0.2 s
    np.testing.assert_array_equal(table["position"].to_numpy()[fixed], gps["position"].to_numpy())
    np.testing.assert_array_equal(table["velocity"].to_numpy()[fixed], gps["velocity"].to_numpy())
    assert np.all(np.isnan(table["velocity"].to_numpy()[np.setdiff1d(np.arange(6001), fixed)]))


def test_a_fix_off_the_sample_grid_is_refused_naming_its_row(accel_gps):
    imu, gps, _ = accel_gps
    off = gps.copy()
    off.loc[2, "time"] += 0.0025  # half a sample: the built-in reaches it by a partial step, a file has no row
    with pytest.raises(ValueError, match=r"^gps: row 3: fix at t = 0.6025 s lies 0.0025 s from the nearest sample"):
        seed_logs.accel_gps_table(imu, off)
    late = gps.copy()
    late.loc[149, "time"] = 31.0
    with pytest.raises(ValueError, match=r"^gps: row 150: fix at t = 31 s lies outside the accelerometer log"):
        seed_logs.accel_gps_table(imu, late)


def test_the_script_writes_the_table_and_refuses_bad_input_with_status_2(tmp_path, accel_gps, capsys):
    imu, gps, table = accel_gps
    imu.to_csv(tmp_path / "imu.csv", index=False)
    gps.to_csv(tmp_path / "gps.csv", index=False)
    assert seed_logs.main(["accel-gps", str(tmp_path), str(tmp_path / "seed000.csv")]) == 0
    pd.testing.assert_frame_equal(pd.read_csv(tmp_path / "seed000.csv"), table)  # every digit read back
    assert seed_logs.main(["scale-bias", str(tmp_path), str(tmp_path / "x.csv")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("seed_logs.py: error: ") and "data.csv" in err


# -- seed 000 -----------------------------------------------------------------------------------------------------


def test_seed000_file_is_the_builtin_filter_nominal_plus_error(accel_gps):
    """Its whole-state estimates are the built-in's nominal + error estimate, and the rest equal, to 1e-9."""
    imu, gps, table = accel_gps
    _, log = _builtin_log(imu, gps)
    builtin = log.calibrate()
    bound, run = _file_run(SEED000, table)
    rows = np.flatnonzero(np.all(np.isfinite(bound.z), axis=1))
    np.testing.assert_array_equal(bound.times[rows], builtin.time)
    estimate = np.stack([builtin.position, builtin.velocity, builtin.bias], axis=1)  # nominal + error
    np.testing.assert_allclose(run.state[rows], estimate, rtol=0, atol=EXACT)
    np.testing.assert_allclose(run.cov[rows], builtin.covariance, rtol=0, atol=EXACT)
    # the priors: the file's predicted whole state is the nominal plus the predicted error
    nominal_p, nominal_v = builtin.position - builtin.error_state[:, 0], builtin.velocity - builtin.error_state[:, 1]
    prior = builtin.prior_state + np.stack([nominal_p, nominal_v, np.zeros_like(nominal_p)], axis=1)
    np.testing.assert_allclose(run.prior_state[rows], prior, rtol=0, atol=EXACT)
    np.testing.assert_allclose(run.prior_cov[rows], builtin.prior_covariance, rtol=0, atol=EXACT)
    np.testing.assert_allclose(run.residual[rows], builtin.residual, rtol=0, atol=EXACT)
    np.testing.assert_allclose(run.innovation_cov[rows], builtin.innovation_cov, rtol=0, atol=EXACT)
    assert log.skip == 0 and run.proper_from == 0
    assert abs(run.loglik - log.loglik()) < EXACT
    assert run.loglik == pytest.approx(21.30210781, abs=5e-9)  # docs/custom-models.md's number
    # the equality is no accident of a flat likelihood: the built-in's default prior (0.1 m/s^2) is another filter
    _, tight = _builtin_log(imu, gps, {"filter.bias_std": 0.1})
    assert abs(tight.loglik() - run.loglik) > 1e-3


def test_seed000_diffuse_conventions_and_their_constant(accel_gps):
    """The built-in's "diffuse" bias (1000 m/s^2, the first fix left out) and the file's exact diffuse bias."""
    imu, gps, table = accel_gps
    _, auto = _builtin_log(imu, gps, {}, prior="auto")  # what `kalcal calibrate` runs
    assert auto.prior == "diffuse" and auto.skip == 1
    _, full = _file_run(SEED000, table)
    _, first = _file_run(SEED000, table.iloc[:41])  # rows 0..40: up to and with the first fix
    # the built-in's likelihood is log p(fixes 2.. | fix 1) under the finite prior: the file's, less fix 1's terms
    assert abs(auto.loglik() - (full.loglik - first.loglik)) < EXACT
    assert auto.loglik() == pytest.approx(30.75720918, abs=5e-9)
    diffuse_sets = ["filter.m0=[[100.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]]", 'filter.diffuse=["bias"]']
    _, exact = _file_run(SEED000, table, diffuse_sets)
    _, exact_first = _file_run(SEED000, table.iloc[:41], diffuse_sets)
    # the file's diffuse bias conditions on one component, fix 1's position (the first to see the bias in
    # the univariate order), and counts its velocity given that; it is proper from fix 1 on
    assert exact.proper_from == 40 and exact.conditioned.sum() == 1 and exact.conditioned[40, 0]
    # the 1000 m/s^2 prior is nearly, not exactly, diffuse: log p(fixes 2.. | fix 1) moves by 1.3e-5 nats
    rest = exact.loglik - exact_first.loglik
    assert auto.loglik() - rest == pytest.approx(1.3e-5, rel=0.05)
    # the constant: a proper prior of variance kappa on the bias gives log L_kappa = llf - 1/2 log kappa + O(1/kappa),
    # llf = loglik + diffuse_term the exact diffuse (statsmodels') likelihood; at kappa = 1e6 the O(1/kappa)
    # and the rounding are 2e-9, while a wrong constant (1/2 log 2 pi = 0.92, or 1/2 log F_inf) is off by > 0.1
    assert abs(full.loglik + 0.5 * np.log(1e6) - (exact.loglik + exact.diffuse_term)) < 1e-8
    assert abs(exact.diffuse_term + 0.5 * np.log(2 * np.pi * 0.02**2)) < 1e-9  # F_inf = (dt^2 / 2 * 40^2)^2 / 1 m^2
    assert exact.diffuse_term == pytest.approx(2.993, abs=5e-4)


def test_seed000_fit_agrees_with_the_builtin_fit(accel_gps):
    from kalcal.scenarios.accel_gps.fit import fit_accel_gps

    imu, gps, table = accel_gps
    scenario, log = _builtin_log(imu, gps)
    builtin = fit_accel_gps(log, scenario, free=["filter.accel_noise_std", "filter.gps_position_std", "filter.gps_velocity_std"])
    fitted = kalcal.fit(str(SEED000), data=table, free="filter.w.1,filter.v.1,filter.v.2")
    assert abs(fitted.loglik - builtin.loglik) < 1e-6  # the same maximum, reached by two searches
    rate = 1.0 / log.period  # the built-in fits the density N; the per-sample std is N sqrt(rate)
    pairs = {"filter.v.1": ("filter.gps_position_std", 1.0), "filter.v.2": ("filter.gps_velocity_std", 1.0)}
    for key, (other, factor) in pairs.items():
        mine, theirs = fitted.parameters[key], builtin.parameters[other]
        assert abs(np.log(mine.value) - 2 * np.log(factor * theirs.value)) < SEARCHES * mine.se
        assert mine.se == pytest.approx(2 * theirs.se, rel=0.05)  # the curvature at the two points
        assert np.log(mine.ci_high) - 2 * np.log(theirs.ci_high) == pytest.approx(0, abs=SEARCHES * mine.se)
    # the accelerometer noise: consistent with 0 on both sides; its upper limit where log L has fallen by 1.92,
    # found by a root search to 1e-4 in u on each side
    mine, theirs = fitted.parameters["filter.w.1"], builtin.parameters["filter.accel_noise_density"]
    assert mine.at_bound and theirs.at_bound
    assert abs(np.log(mine.ci_high) - 2 * np.log(theirs.ci_high * np.sqrt(rate))) < 2 * 2e-4 + 1e-6
    # docs/custom-models.md's table
    assert [round(fitted.parameters[k].value, n) for k, n in (("filter.v.1", 5), ("filter.v.2", 8))] == [1.14722, 1.5489e-3]
    assert round(mine.ci_high, 5) == 0.03945 and round(theirs.ci_high, 6) == 0.014045
    assert round(fitted.loglik, 7) == round(builtin.loglik, 7) == 23.3022729


# -- seed 003 -----------------------------------------------------------------------------------------------------


def _scale_bias_builtin(data, settings=None, prior="diffuse"):
    from kalcal.scenarios.scale_bias.calibration import calibrate_scale_bias

    scenario = resolve("scale-bias", settings, None)
    arrays = (data[c].to_numpy() for c in ("time", "reference", "sensor"))
    return scenario, calibrate_scale_bias(scenario, *arrays, prior=prior)


def _proper_sets() -> list[str]:
    """The proper-prior variant's --set values, as the example file's comment gives them."""
    text = SEED003.read_text(encoding="utf-8")
    return re.findall(r"--set '([^']+)'", text)


def _same_run(run, builtin, start):
    rows = slice(start, None)
    np.testing.assert_allclose(run.state[rows], builtin.theta[rows], rtol=0, atol=EXACT)
    np.testing.assert_allclose(run.cov[rows], builtin.covariance[rows], rtol=0, atol=EXACT)
    np.testing.assert_allclose(run.residual[rows, 0], builtin.residual[rows], rtol=0, atol=EXACT)
    np.testing.assert_allclose(run.innovation_cov[rows, 0, 0], builtin.innovation_var[rows], rtol=0, atol=EXACT)


def test_seed003_file_is_the_builtin_diffuse_calibration(scale_bias):
    from kalcal.scenarios.scale_bias.likelihood import diffuse_loglik

    scenario, builtin = _scale_bias_builtin(scale_bias)
    bound, run = _file_run(SEED003, scale_bias)
    assert load_model_file(SEED003).filter.v[0, 0] == scenario.filter_noise_variance()  # the file's v is the built-in's R
    np.testing.assert_array_equal(bound.times, builtin.time)
    # both are determined by the first two samples (two different sensor readings): the file's posterior is
    # proper from row 1, the built-in's information-form start ends there too
    assert run.proper_from == 1 and run.conditioned.sum() == 2
    assert np.all(np.isnan(builtin.theta[:1])) and np.all(np.isfinite(builtin.theta[1:]))
    _same_run(run, builtin, 1)
    value, samples, _ = diffuse_loglik(*(scale_bias[c].to_numpy() for c in ("reference", "sensor")),
                                       np.sqrt(scenario.filter_noise_variance()), 0.0)
    assert samples == int(np.count_nonzero(run.measured & ~run.conditioned)) == 298
    assert abs(run.loglik - value) < EXACT
    assert value == pytest.approx(49.50673624, abs=5e-9)


def test_seed003_proper_prior_variant_is_the_builtin_settings_prior(scale_bias):
    scenario, builtin = _scale_bias_builtin(scale_bias, prior="settings")
    sets = _proper_sets()
    assert len(sets) == 3
    scenario_file = load_model_file(SEED003, sets)
    prior = scenario.filter_prior()
    np.testing.assert_array_equal(scenario_file.filter.x0, prior.mean)  # the comment's digits are the built-in's
    np.testing.assert_array_equal(scenario_file.filter.m0, prior.cov)
    _, run = _file_run(SEED003, scale_bias, sets)
    assert run.proper_from == 0 and not run.conditioned.any()
    _same_run(run, builtin, 0)
    residual = builtin.residual[:, None]
    assert abs(run.loglik - innovation_loglik(residual, builtin.innovation_var[:, None, None])) < EXACT


def test_seed003_without_sensor_noise_is_the_file_with_the_reference_noise_alone(scale_bias):
    """verify's comparison runs the built-in with truth.sensor_noise_std = 0, whose filter's R is then 0.2^2:
    the file with v = 0.04 is that filter (the errors in variables that the sensor noise adds to the truth
    cannot be stated in a file)."""
    scenario, builtin = _scale_bias_builtin(scale_bias, {"truth.sensor_noise_std": 0.0})
    assert scenario.filter_noise_variance() == 0.2**2
    _, run = _file_run(SEED003, scale_bias, ["filter.v=[[0.04000000000000001]]"])  # 0.2**2 in floating point
    _same_run(run, builtin, 1)


def test_seed003_fit_agrees_with_the_builtin_fit(scale_bias):
    from kalcal.scenarios.scale_bias.fit import fit_scale_bias

    scenario = resolve("scale-bias", None, None)
    arrays = (scale_bias[c].to_numpy() for c in ("time", "reference", "sensor"))
    builtin = fit_scale_bias(scenario, *arrays, free=["filter.reference_noise_std"])  # the drift held at 0
    fitted = kalcal.fit(str(SEED003), data=scale_bias)  # the default: every positive diagonal entry, v alone
    assert list(fitted.parameters) == ["filter.v"]
    assert abs(fitted.loglik - builtin.loglik) < 1e-6
    mine, theirs = fitted.parameters["filter.v"], builtin.parameters["filter.reference_noise_std"]
    assert abs(np.log(mine.value) - 2 * np.log(theirs.value)) < SEARCHES * mine.se
    assert mine.se == pytest.approx(2 * theirs.se, rel=0.05)
    assert round(mine.value, 7) == 0.0400559 and round(theirs.value, 6) == 0.20014
    assert round(fitted.loglik, 7) == round(builtin.loglik, 7) == 49.5068609
    for end in ("ci_low", "ci_high"):
        assert abs(np.log(getattr(mine, end)) - 2 * np.log(getattr(theirs, end))) < SEARCHES * mine.se


def test_seed003_with_drift_the_file_prior_carries_the_first_step(scale_bias):
    """The built-in predicts P^- = P_0 + Q before its first sample; a file's prior is at row 0, before row 0's
    measurement, so a drifting theta's file gives m0 = P_0 + Q (and w = q^2 I per sample)."""
    q = 0.01
    scenario, builtin = _scale_bias_builtin(scale_bias, {"filter.parameter_drift_std": q}, prior="settings")
    prior = scenario.filter_prior()
    m0 = (prior.cov + q**2 * np.eye(2)).tolist()
    sets = [*_proper_sets()[:2], f"filter.m0={m0}", f"filter.w=[[{q**2!r}, 0.0], [0.0, {q**2!r}]]"]
    _, run = _file_run(SEED003, scale_bias, sets)
    _same_run(run, builtin, 0)
    _, without = _file_run(SEED003, scale_bias, [*_proper_sets()[:2], f"filter.m0={prior.cov.tolist()}", sets[-1]])
    assert abs(without.state[0] - builtin.theta[0]).max() > 1e-6  # the step is not negligible: the prior must carry it


def test_seed000_equals_what_kalcal_calibrate_accel_gps_runs_with_init_prior_and_bias_std_1000(accel_gps):
    """The command line of docs/custom-models.md: `--init prior --set scenario.integration=euler --set
    filter.bias_std=1000` is the filter above (a log's calibration defaults to the trapezoid scheme, another model)."""
    imu, gps, table = accel_gps
    euler = {"scenario.integration": "euler", "filter.bias_std": 1000.0}
    result = kalcal.calibrate("accel-gps", imu=imu, gps=gps, settings=euler, init="prior", windows=1, settings_sigma=False)
    bound, run = _file_run(SEED000, table)
    rows = np.flatnonzero(np.all(np.isfinite(bound.z), axis=1))
    for i, name in enumerate(("position", "velocity", "bias")):
        np.testing.assert_allclose(run.state[rows, i], result.columns[name], rtol=0, atol=EXACT)
        np.testing.assert_allclose(np.sqrt(run.cov[rows, i, i]), result.columns[f"{name}_std"], rtol=0, atol=EXACT)
    trapezoid = kalcal.calibrate("accel-gps", imu=imu, gps=gps, settings={"filter.bias_std": 1000.0}, init="prior",
                                 windows=1, settings_sigma=False)
    assert np.abs(trapezoid.columns["position"] - run.state[rows, 0]).max() > 1e-3  # the default scheme is not the file


# -- through the command line: the same commands a user runs -------------------------------------------------------


def _cli(*args):
    from typer.testing import CliRunner

    from kalcal.cli import app

    result = CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    return result


def test_kalcal_calibrate_of_the_seed000_file_is_kalcal_calibrate_accel_gps_as_the_file_states_it(tmp_path, accel_gps):
    """`kalcal calibrate examples/accel_gps_seed000.toml --data LOG` and `kalcal calibrate accel-gps --imu --gps
    --init prior --set scenario.integration=euler --set filter.bias_std=1000`: every estimate, 1-sigma,
    innovation and NIS at the fixes to 1e-9, read back from the two runs' estimates.csv (written with every digit)."""
    imu, gps, table = accel_gps
    for name, frame in (("imu", imu), ("gps", gps), ("seed000", table)):
        frame.to_csv(tmp_path / f"{name}.csv", index=False)
    _cli("calibrate", SEED000, "--data", tmp_path / "seed000.csv", "--out", tmp_path / "file")
    _cli("calibrate", "accel-gps", "--imu", tmp_path / "imu.csv", "--gps", tmp_path / "gps.csv", "--init", "prior",
         "--set", "scenario.integration=euler", "--set", "filter.bias_std=1000", "--out", tmp_path / "builtin")
    mine = pd.read_csv(tmp_path / "file" / "estimates.csv")
    theirs = pd.read_csv(tmp_path / "builtin" / "estimates.csv")
    fixes = mine[mine["position_innovation"].notna()].reset_index(drop=True)
    assert len(fixes) == len(theirs) == 150
    np.testing.assert_array_equal(fixes["time"], theirs["time"])
    for column in ("position", "velocity", "bias", "position_std", "velocity_std", "bias_std", "nis"):
        np.testing.assert_allclose(fixes[column], theirs[column], rtol=0, atol=EXACT, err_msg=column)
    # the built-in writes the innovations whitened by the Cholesky factor of S_k, whose first component is the
    # position's innovation over its std (the second mixes in the correlation, which estimates.csv does not hold:
    # the raw innovations and S_k are equal above, test_seed000_file_is_the_builtin_filter_nominal_plus_error)
    normalized = fixes["position_innovation"] / fixes["position_innovation_std"]
    np.testing.assert_allclose(normalized, theirs["innovation_position"], rtol=0, atol=EXACT)
    summary = json.loads((tmp_path / "file" / "summary.json").read_text())
    assert summary["estimate"]["bias"] == pytest.approx(theirs["bias"].iloc[-1], rel=0, abs=EXACT)
    assert summary["loglik"] == pytest.approx(21.30210781, abs=5e-9)  # the built-in's, test_seed000_file_is_...


def test_kalcal_calibrate_of_the_seed003_file_is_kalcal_calibrate_scale_bias(tmp_path, scale_bias):
    """`kalcal calibrate examples/scale_bias_seed003.toml --data LOG` and `kalcal calibrate scale-bias --data LOG`
    (a log with no prior given runs the diffuse start): theta and its 1-sigmas at every row to 1e-9, the rows
    before the two starts are determined NaN on both sides."""
    scale_bias.to_csv(tmp_path / "data.csv", index=False)
    _cli("calibrate", SEED003, "--data", tmp_path / "data.csv", "--out", tmp_path / "file")
    _cli("calibrate", "scale-bias", "--data", tmp_path / "data.csv", "--out", tmp_path / "builtin")
    mine = pd.read_csv(tmp_path / "file" / "estimates.csv")
    theirs = pd.read_csv(tmp_path / "builtin" / "estimates.csv")
    assert len(mine) == len(theirs) == 300
    np.testing.assert_array_equal(mine["time"], theirs["time"])
    for column in ("theta1", "theta2", "theta1_std", "theta2_std"):
        np.testing.assert_array_equal(mine[column].isna(), theirs[column].isna(), err_msg=column)
        np.testing.assert_allclose(mine[column], theirs[column], rtol=0, atol=EXACT, err_msg=column)
    summary = json.loads((tmp_path / "file" / "summary.json").read_text())
    assert summary["loglik"] == pytest.approx(49.50673624, abs=5e-9)  # the built-in's diffuse_loglik, above


def test_verify_of_the_seed003_file_over_the_builtins_regressors_agrees_with_kalcal_verify_scale_bias(tmp_path):
    """`kalcal verify scale-bias` at truth.sensor_noise_std = 0 (and a fixed scale, bias and no drift in the
    truth, so that its sensor readings, the regressors h_k = [sensor_k, 1], are the same in every realization:
    the built-in's signal, deterministic) against the seed 003 file over a log of those readings (its proper-prior
    variant, v = 0.2^2, the truth's theta the built-in's, m0 = 0). "Agrees" means: the same filter, so the
    same P_k at every update k to rounding (1e-9 relative), and the same true error covariance, which the
    file's exact analysis gives and each side's ensemble estimates: the errors are linear in the reference's
    Gaussian noise, so each diagonal entry's sample variance has standard error sqrt(2/(n-1)) of it; each
    side lies within 4.5 of them (a false alarm below 1e-5 per entry, fixed seeds)."""
    import warnings

    settings = {"truth.sensor_noise_std": 0.0, "truth.scale_error_std": 0.0, "truth.bias_std": 0.0,
                "truth.parameter_drift_std": 0.0, "filter.scale_error_std": 0.02, "filter.bias_std": 0.1}
    logs = [kalcal.simulate("scale-bias", seed, settings=settings).logs["data"] for seed in (1, 2)]
    np.testing.assert_array_equal(logs[0]["sensor"], logs[1]["sensor"])  # the regressors do not depend on the draw
    logs[0].to_csv(tmp_path / "regressors.csv", index=False)
    n = 4000
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        builtin = kalcal.verify("scale-bias", n, seed=1, settings=settings)
        sets = dict(s.split("=", 1) for s in _proper_sets())
        sets |= {"filter.v": "[[0.04000000000000001]]", "truth.m0": "[[0.0, 0.0], [0.0, 0.0]]",
                 "truth.x0": f"[{1 / 0.99!r}, {0.05 / 0.99!r}]"}  # theta(a, b) at the built-in truth's a, b
        mine = kalcal.verify(str(SEED003), n, seed=2, settings=sets, data=tmp_path / "regressors.csv")
    theirs, ours = builtin.raw_summary["final"], mine.raw_summary["final"]
    assert theirs["time"] == ours["time"] == 30.0
    np.testing.assert_allclose(np.array(ours["filter_covariance"]), np.array(theirs["filter_covariance"]), rtol=1e-9)
    # P_k at every update k, not the last alone: the same filter over the same regressors and times
    np.testing.assert_allclose(mine.statistics["time"].values, builtin.statistics["time"].values, rtol=0, atol=1e-12)
    np.testing.assert_allclose(mine.statistics["filter_cov"].values, builtin.statistics["filter_cov"].values, rtol=1e-9)
    exact = np.diag(np.array(ours["exact_error_covariance"]))
    bound = 4.5 * np.sqrt(2.0 / (n - 1)) * exact
    for side in (theirs, ours):
        assert np.all(np.abs(np.diag(np.array(side["ensemble_covariance"])) - exact) < bound)
    # the filter believes a prior spread the truth lacks: its P_k exceeds the true covariance, which both see
    assert np.all(np.diag(np.array(ours["filter_covariance"])) > exact)
