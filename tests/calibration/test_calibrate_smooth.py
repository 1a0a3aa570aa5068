"""Smoothing a calibration run (--smooth) and the update forms of calibrate (--form).

Oracles: the dense joint Gaussian of the error states given every fix (for the smoother on a real
calibration run), the compiled Joseph loop against the numpy loops of the three forms, and the smoothed
errors' own spread over seeds.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pandas as pd
import pytest
from scipy import stats
from scipy.linalg import block_diag
from typer.testing import CliRunner

from kalcal.scenarios.accel_gps.calibration import calibrate_accel_gps
from kalcal.scenarios.accel_gps.evaluation import python_filter as _python_filter
from kalcal.scenarios.accel_gps.smoothing import smooth_calibration
from kalcal.cli import app
from kalcal.core.steps import interval_transition
from kalcal.errors import ConfigError, DataError
from kalcal.scenarios.accel_gps.mechanization import integrate
from kalcal.filters.sequential import sequential_filter
from kalcal.scenarios.accel_gps.discretization import error_transition
from kalcal.scenarios import build_scenario
from kalcal.scenarios.accel_gps.sampled import sample_accel_gps_logs
from tests._helpers import assert_close, cov_atol

SMOOTHED_COLUMNS = [
    "smoothed_position", "smoothed_velocity", "smoothed_bias",
    "smoothed_position_std", "smoothed_velocity_std", "smoothed_bias_std",
]


def transition(elapsed):
    """exp(A s) of the error state with a constant bias, (..., 3, 3): [[1, s, -s^2/2], [0, 1, -s], [0, 0, 1]]."""
    s = np.asarray(elapsed, dtype=float)
    return error_transition(0.0, s, s, 1.0, "euler")[0]


def _scenario(*extra):
    return build_scenario("accel-gps", assignments=["scenario.duration=10", *extra])


def _calibrate(scenario, logs, i=0, **kwargs):
    return calibrate_accel_gps(
        scenario, logs.sample_time, logs.accel[i], logs.fix_time, logs.gps_position[i], logs.gps_velocity[i], **kwargs
    )


def _dense_error_states(scenario, dz):
    """E and Cov of the error states at the fixes given every dz, by one solve over the stacked vector."""
    model = scenario.filter_model()
    phi, q = interval_transition(model.phi, model.gamma, model.w, model.steps_per_update)
    n_fixes, d = dz.shape[0], model.state_dim
    # x_k = sum_j Phi^{k-j} w_j + Phi^k x_0 for k = 1..K
    a = np.zeros((n_fixes * d, (n_fixes + 1) * d))
    for k in range(n_fixes):
        for j in range(k + 2):
            a[k * d:(k + 1) * d, j * d:(j + 1) * d] = np.linalg.matrix_power(phi, k + 1 - j if j else k + 1)
    cov = a @ block_diag(model.m0, *([q] * n_fixes)) @ a.T
    h = block_diag(*([model.h] * n_fixes))
    s = h @ cov @ h.T + block_diag(*([model.v] * n_fixes))
    cross = cov @ h.T
    mean = cross @ np.linalg.solve(s, dz.reshape(-1))
    post = cov - cross @ np.linalg.solve(s, cross.T)
    return mean.reshape(n_fixes, d), np.stack([post[k * d:(k + 1) * d, k * d:(k + 1) * d] for k in range(n_fixes)])


def test_smoothed_calibration_equals_the_dense_joint_gaussian():
    scenario = _scenario()
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(3), 1)
    result = _calibrate(scenario, logs)
    smoothed = smooth_calibration(result)
    p_c, v_c = integrate(logs.accel[0], scenario.scenario.sample_period, *scenario.nominal_start(), "euler")
    fix = logs.fix_index
    dz = np.stack([logs.gps_position[0] - p_c[fix], logs.gps_velocity[0] - v_c[fix]], axis=-1)
    mean, cov = _dense_error_states(scenario, dz)
    sigma = np.sqrt(np.diagonal(cov, axis1=1, axis2=2))
    assert_close(smoothed.error_state, mean, rtol=1e-9, atol=1e-9 * sigma, what="smoothed error state")
    assert_close(smoothed.covariance, cov, atol=cov_atol(cov, 1e-9), what="smoothed covariance")
    assert_close(smoothed.position, p_c[fix] + mean[:, 0], rtol=1e-12, atol=1e-9 * sigma[:, 0], what="position")
    assert_close(smoothed.velocity, v_c[fix] + mean[:, 1], rtol=1e-12, atol=1e-9 * sigma[:, 1], what="velocity")
    np.testing.assert_array_equal(smoothed.bias, smoothed.error_state[:, 2])
    # The last fix is the filter's; every smoothed sigma is at most the filter's.
    np.testing.assert_allclose(smoothed.error_state[-1], result.error_state[-1], rtol=1e-12)
    assert np.all(smoothed.std <= result.std * (1 + 1e-12))


def test_smoothed_position_errors_are_standard_normal_over_seeds():
    """Euler against the discrete truth (no model error): (p_s - p) / sigma_s ~ N(0, 1) at the first fix."""
    scenario = _scenario("scenario.truth=discrete")
    n_seeds = 40
    z = np.empty((n_seeds, 2))
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(77), n_seeds)
    for i in range(n_seeds):
        smoothed = smooth_calibration(_calibrate(scenario, logs, i))
        z[i, 0] = (smoothed.position[0] - logs.position[i, logs.fix_index[0]]) / smoothed.std[0, 0]
        z[i, 1] = (smoothed.bias[0] - logs.bias[i, logs.fix_index[0]]) / smoothed.std[0, 2]
    for column in z.T:
        assert abs(column.mean()) <= 3.5 / np.sqrt(n_seeds), f"mean {column.mean():.3f}"
        low = stats.chi2.ppf(0.0005, n_seeds) / n_seeds
        high = stats.chi2.isf(0.0005, n_seeds) / n_seeds
        assert low <= np.mean(column**2) <= high, f"mean square {np.mean(column**2):.3f}"


def test_smoothing_with_a_scale_factor_state():
    """The smoother runs on the filter's [dp, dv, b', s'] and converts as the filter does."""
    scenario = _scenario("truth.scale_std=1e-3")
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(8), 1)
    result = _calibrate(scenario, logs)
    smoothed = smooth_calibration(result)
    assert smoothed.error_state.shape == result.error_state.shape == (50, 4)
    np.testing.assert_allclose(smoothed.error_state[-1], result.error_state[-1], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(smoothed.covariance[-1], result.covariance[-1], rtol=1e-12, atol=1e-20)
    np.testing.assert_array_equal(smoothed.scale, smoothed.error_state[:, 3])
    assert np.all(smoothed.std[:, :2] <= result.std[:, :2] * (1 + 1e-9))


def test_smoothing_needs_the_priors():
    scenario = _scenario()
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(4), 1)
    bare = dataclasses.replace(_calibrate(scenario, logs), prior_covariance=None)
    with pytest.raises(DataError, match="priors and transitions"):
        smooth_calibration(bare)


# --------------------------------------------------------------------------------------------------
# the update forms on the calibrate path


def _random_fixes(seed, n=60):
    rng = np.random.default_rng(seed)
    phis = transition(rng.uniform(0.1, 0.3, n))
    a = rng.standard_normal((n, 3, 2)) * 1e-3
    qs = a @ np.swapaxes(a, 1, 2)  # singular, as the accel-gps noise (no bias noise)
    v = np.array([np.diag(rng.uniform(0.5, 2.0, 2)) for _ in range(n)])
    return phis, qs, np.eye(3)[:2], v, rng.standard_normal((n, 2)), np.zeros(3), np.diag([100.0, 1.0, 0.01])


@pytest.mark.parametrize("form", ["joseph", "standard", "sqrt"])
def test_numpy_loops_of_every_form_equal_the_compiled_joseph_loop(form):
    phis, qs, h, v, z, x0, m0 = _random_fixes(16)
    compiled = sequential_filter(phis, qs, h, v, z, x0, m0)
    reference = _python_filter(phis, qs, h, v, z, x0, m0, form)
    assert compiled._fields[-2:] == ("prior_state", "prior_cov")
    for name, got, want in zip(compiled._fields, compiled, reference):
        if name.endswith("cov"):
            assert_close(got, want, atol=cov_atol(want, 1e-10), what=f"{form} {name}")
        else:
            np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12, err_msg=f"{form} {name}")


@pytest.mark.parametrize("extra", [(), ("truth.bias_walk_std=2e-5",)], ids=["constant bias", "bias walk"])
def test_the_three_forms_agree_through_calibrate(extra):
    scenario = _scenario("scenario.integration=trapezoid", *extra)
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(5), 1)
    results = {form: _calibrate(scenario, logs, init="first-fix", form=form) for form in ("joseph", "standard", "sqrt")}
    joseph = results["joseph"]
    assert joseph.form == "joseph" and results["sqrt"].form == "sqrt"
    sigma = joseph.std
    for form in ("standard", "sqrt"):
        other = results[form]
        assert_close(other.error_state, joseph.error_state, atol=1e-9 * sigma, what=f"{form} states")
        assert_close(other.covariance, joseph.covariance, atol=cov_atol(joseph.covariance, 1e-9), what=f"{form} P")
        assert_close(other.prior_covariance, joseph.prior_covariance, atol=cov_atol(joseph.prior_covariance, 1e-9))
        np.testing.assert_allclose(other.innovation_cov, joseph.innovation_cov, rtol=1e-9)
        smoothed, reference = smooth_calibration(other), smooth_calibration(joseph)
        assert_close(smoothed.error_state, reference.error_state, atol=1e-9 * reference.std, what=f"{form} smoothed")


def test_unknown_form_is_refused():
    scenario = _scenario()
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(6), 1)
    with pytest.raises(ConfigError, match="--form: expected one of joseph, standard, sqrt, got 'qr'"):
        _calibrate(scenario, logs, form="qr")


# --------------------------------------------------------------------------------------------------
# the command line


def _invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim")
    result = _invoke("simulate", "accel-gps", "--seed", "2", "--out", out, "--set", "scenario.duration=10")
    assert result.exit_code == 0, result.output + result.stderr
    return out


def test_calibrate_smooth_writes_smoothed_columns_and_summary(simulated, tmp_path):
    args = ("calibrate", "accel-gps", "--imu", simulated / "imu.csv", "--gps", simulated / "gps.csv", "--set", "filter.bias_std=0.1")
    plain = _invoke(*args, "--out", tmp_path / "plain")
    assert plain.exit_code == 0, plain.stderr
    result = _invoke(*args, "--out", tmp_path / "smooth", "--smooth", "--form", "sqrt")
    assert result.exit_code == 0, result.output + result.stderr
    assert "smoothed (RTS) at the first fix" in result.output

    table = pd.read_csv(tmp_path / "smooth" / "estimates.csv")
    base = pd.read_csv(tmp_path / "plain" / "estimates.csv")
    assert list(table.columns) == list(base.columns) + SMOOTHED_COLUMNS
    assert not any(c.startswith("smoothed") for c in base.columns)
    # the sqrt form's filter columns agree with the default Joseph run's
    for name in ("position", "velocity", "bias"):
        assert_close(table[name], base[name], rtol=1e-12, atol=1e-9 * base[f"{name}_std"].to_numpy(), what=name)
        assert np.all(table[f"smoothed_{name}_std"] <= table[f"{name}_std"] * (1 + 1e-9))
    last = table.iloc[-1]
    assert last["smoothed_bias"] == pytest.approx(last["bias"], rel=1e-9)

    summary = json.loads((tmp_path / "smooth" / "summary.json").read_text())
    assert summary["form"] == "sqrt"
    assert json.loads((tmp_path / "plain" / "summary.json").read_text())["form"] == "joseph"
    assert "smoothed" not in json.loads((tmp_path / "plain" / "summary.json").read_text())
    smoothed = summary["smoothed"]
    assert smoothed["method"] == "rts" and smoothed["time"] == pytest.approx(table["time"].iloc[0])
    assert smoothed["bias"] == pytest.approx(table["smoothed_bias"].iloc[0], rel=1e-12)
    assert smoothed["position_std"] == pytest.approx(table["smoothed_position_std"].iloc[0], rel=1e-12)
    assert np.array(smoothed["covariance"]).shape == (3, 3)
    assert set(smoothed["mean_std_ratio"]) == {"position", "velocity", "bias"}
    assert all(0 < r <= 1 + 1e-9 for r in smoothed["mean_std_ratio"].values())


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--form", "qr"), "--form: expected one of joseph, standard, sqrt"),
        (("scale-bias", "--data", "x.csv", "--smooth"), "--smooth: not available for scale-bias"),
        (("scale-bias", "--data", "x.csv", "--form", "sqrt"), "--form: not available for scale-bias"),
    ],
)
def test_bad_form_or_smooth_is_one_line_and_status_2(simulated, tmp_path, args, message):
    if args[0] == "scale-bias":
        command = ("calibrate", *args, "--out", tmp_path)
    else:
        command = ("calibrate", "accel-gps", "--imu", simulated / "imu.csv", "--gps", simulated / "gps.csv", "--out", tmp_path, *args)
    result = _invoke(*command)
    assert result.exit_code == 2
    assert message in result.stderr and result.stderr.count("\n") == 1
