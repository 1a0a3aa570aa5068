"""A prepared log's likelihood against the dense joint Gaussian of all fixes, and its settings' keys."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from kalcal.scenarios.accel_gps.calibration import calibrate_accel_gps, prepare_accel_gps_log
from kalcal.scenarios.accel_gps.evaluation import DIFFUSE_BIAS_STD, latency_map
from kalcal.core.likelihood import innovation_loglik
from kalcal.errors import ConfigError
from kalcal.scenarios.accel_gps.mechanization import integrate
from kalcal.scenarios import build_scenario
from kalcal.scenarios.accel_gps.sampled import sample_accel_gps_logs

#: a small log: 2 s at 100 Hz with 10 Hz fixes (201 samples, 20 fixes)
SMALL = ["scenario.duration=2", "scenario.imu_rate=100", "scenario.gps_rate=10"]


def _small(*extra, seed=0):
    scenario = build_scenario("accel-gps", assignments=[*SMALL, *extra])
    logs = sample_accel_gps_logs(scenario, np.random.default_rng(seed), 1)
    return scenario, logs


def _dense_loglik(scenario, logs, dz, *, values=None, latency=0.0, fix_std=None, bias_prior=None, skip=0):
    """log N(dz; 0, C) with C the covariance of all dz stacked, built from the per-sample model
    (scenario.filter_model(): phi, gamma, w per sample), the prior N(0, M0) at t = 0 and a fix on every
    m-th sample: dz_k = H_L x(t_k) + v_k; with ``skip`` the conditional density given the first fixes."""
    values = values or {}
    model = scenario.filter_model()
    phi, gamma, w = model.phi, model.gamma, model.w
    if "filter.accel_noise_std" in values:
        w = w.copy()
        w[0, 0] = values["filter.accel_noise_std"] ** 2
    m, n_fix = scenario.scenario.steps_per_update, scenario.scenario.n_updates
    phi_k, q_k = np.eye(3), np.zeros((3, 3))
    for _ in range(m):
        phi_k, q_k = phi @ phi_k, phi @ q_k @ phi.T + gamma @ w @ gamma.T
    m0 = model.m0.copy()
    if bias_prior is not None:
        m0[2, 2] = bias_prior**2
    covs = [phi_k @ m0 @ phi_k.T + q_k]
    for _ in range(n_fix - 1):
        covs.append(phi_k @ covs[-1] @ phi_k.T + q_k)
    h = latency_map(latency)[0]
    joint = np.zeros((2 * n_fix, 2 * n_fix))
    for i in range(n_fix):
        for j in range(i + 1):
            cross = h @ np.linalg.matrix_power(phi_k, i - j) @ covs[j] @ h.T
            joint[2 * i : 2 * i + 2, 2 * j : 2 * j + 2] = cross
            joint[2 * j : 2 * j + 2, 2 * i : 2 * i + 2] = cross.T
    if fix_std is None:
        fix_std = (np.full(n_fix, values.get("filter.gps_position_std", np.sqrt(model.v[0, 0]))),
                   np.full(n_fix, values.get("filter.gps_velocity_std", np.sqrt(model.v[1, 1]))))
    joint[np.diag_indices(2 * n_fix)] += np.column_stack(fix_std).ravel() ** 2
    if dz is None:
        return joint
    flat = dz.ravel()
    if not skip:
        return stats.multivariate_normal(np.zeros(flat.size), joint).logpdf(flat)
    n = 2 * skip  # the conditional Gaussian of the rest given the first fixes (its Schur complement)
    gain = np.linalg.solve(joint[:n, :n], joint[:n, n:]).T
    cov = joint[n:, n:] - gain @ joint[:n, n:]
    return stats.multivariate_normal(gain @ flat[:n], 0.5 * (cov + cov.T)).logpdf(flat[n:])


def _dz(scenario, logs):
    """The fixes less the nominal integrated from the prior means at t = 0 (fixes on samples)."""
    p0, v0 = scenario.nominal_start()
    dt = scenario.scenario.sample_period
    p, v = integrate(logs.accel[0], dt, p0, v0, scenario.scenario.integration)
    on = np.arange(1, scenario.scenario.n_updates + 1) * scenario.scenario.steps_per_update
    return np.column_stack([logs.gps_position[0] - p[on], logs.gps_velocity[0] - v[on]])


def _prepare(scenario, logs, **kwargs):
    return prepare_accel_gps_log(
        scenario, logs.sample_time, logs.accel[0], logs.fix_time, logs.gps_position[0], logs.gps_velocity[0],
        imu_rate=scenario.scenario.imu_rate, gps_rate=scenario.scenario.gps_rate, **kwargs,
    )


def _close(got, want):
    assert abs(got - want) <= 1e-8 * max(1.0, abs(want)), (got, want)


@pytest.mark.parametrize("integration", ["euler", "trapezoid"])
@pytest.mark.parametrize(
    "extra",
    [
        (),
        ("truth.bias_correlation_time=3", "truth.bias_std=0.05"),
        ("truth.bias_walk_std=0.001",),
        ("truth.bias_correlation_time=5", "truth.bias_walk_std=0.002"),
    ],
    ids=["constant", "gauss-markov", "walk", "markov-and-walk"],
)
def test_loglik_equals_the_dense_joint_density(integration, extra):
    scenario, logs = _small(f"scenario.integration={integration}", "scenario.truth=discrete", *extra)
    log = _prepare(scenario, logs)
    dz = _dz(scenario, logs)
    _close(log.loglik(), _dense_loglik(scenario, logs, dz))
    values = {"filter.accel_noise_std": 0.05, "filter.gps_position_std": 2.0, "filter.gps_velocity_std": 0.1}
    _close(log.loglik(values), _dense_loglik(scenario, logs, dz, values=values))


def test_loglik_with_latency_equals_the_dense_density_with_h_l():
    """The latency's algebra (H_L on the state at the stamp, the fix against the nominal at t - L); the
    nominal at t - L is the log's own, integrated by the scheme."""
    scenario, logs = _small("scenario.truth=discrete")
    log = _prepare(scenario, logs)
    for latency in (0.02, -0.013):
        p, v = log.nominal(latency)[:2]
        dz = np.column_stack([logs.gps_position[0] - p, logs.gps_velocity[0] - v])
        _close(log.loglik({"filter.gps_latency": latency}), _dense_loglik(scenario, logs, dz, latency=latency))


def test_loglik_with_per_fix_std_multipliers():
    scenario, logs = _small("scenario.truth=discrete")
    rng = np.random.default_rng(5)
    column_p, column_v = rng.uniform(0.5, 2.0, logs.fix_time.size), rng.uniform(0.02, 0.08, logs.fix_time.size)
    column_v[3] = np.nan  # takes the filter's setting, not multiplied
    log = _prepare(scenario, logs, position_std=column_p, velocity_std=column_v)
    values = {"log.position_std_multiplier": 1.7, "log.velocity_std_multiplier": 0.6, "filter.gps_velocity_std": 0.05}
    std_v = np.where(np.isfinite(column_v), 0.6 * column_v, 0.05)
    want = _dense_loglik(scenario, logs, _dz(scenario, logs), fix_std=(1.7 * column_p, std_v))
    _close(log.loglik(values), want)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_diffuse_prior_is_the_conditional_density_given_the_first_fix(seed):
    """The diffuse prior's likelihood is the density of the fixes after the first given the first, within
    a bound from theory. The bias enters the fixes as a rank-one term, C(s) = C0 + s^2 g g^T, so the
    conditional log-density is, exactly, L(s) = L0 - 0.5 log((1 + s^2 I) / (1 + s^2 I1))
    + 0.5 s^2 (u^2 / (1 + s^2 I) - u1^2 / (1 + s^2 I1)), with I = g^T C0^-1 g, u = g^T C0^-1 dz over all
    fixes and I1, u1 over the first. Its limit as s grows is the density given the first fix with the
    bias's prior gone; the filter's DIFFUSE_BIAS_STD s0 differs from it by 0.5 (1/I1 + b1^2) / s0^2 to
    first order (b1 = u1 / I1, the first fix's own bias estimate), the bound asserted with 5% for the
    second order."""
    scenario, logs = _small("scenario.truth=discrete", seed=seed)
    log = _prepare(scenario, logs, prior="diffuse")
    assert log.skip == 1 and log.prior == "diffuse"
    dz = _dz(scenario, logs).ravel()
    c0 = _dense_loglik(scenario, logs, None, bias_prior=0.0)
    rank_one = _dense_loglik(scenario, logs, None, bias_prior=1.0) - c0  # g g^T
    g = rank_one[:, 0] / np.sqrt(rank_one[0, 0])
    assert np.allclose(rank_one, np.outer(g, g), rtol=1e-9, atol=1e-12 * np.abs(rank_one).max())

    def information(n):  # I and u of the first n measurements, by Cholesky solves
        factor = np.linalg.cholesky(c0[:n, :n])
        a, b = np.linalg.solve(factor, g[:n]), np.linalg.solve(factor, dz[:n])
        return float(a @ a), float(a @ b)

    info, u = information(dz.size)
    info1, u1 = information(2)
    base = (stats.multivariate_normal(np.zeros(dz.size), c0).logpdf(dz)
            - stats.multivariate_normal(np.zeros(2), c0[:2, :2]).logpdf(dz[:2]))
    limit = base - 0.5 * np.log(info / info1) + 0.5 * (u**2 / info - u1**2 / info1)  # s -> infinity
    bound = 1.05 * 0.5 * (1.0 / info1 + (u1 / info1) ** 2) / DIFFUSE_BIAS_STD**2
    # the filter at s0 = 1e3 carries an absolute rounding of about s0^2 eps per update, 3e-8 over K = 150
    # (observed 2.6e-10 at most); a wrong skip or prior moves L by O(1)
    rounding = DIFFUSE_BIAS_STD**2 * np.finfo(float).eps * logs.fix_time.size
    assert abs(log.loglik() - limit) <= bound + rounding, (log.loglik() - limit, bound)
    s2 = DIFFUSE_BIAS_STD**2
    exact = base - 0.5 * np.log((1 + s2 * info) / (1 + s2 * info1)) + 0.5 * s2 * (u**2 / (1 + s2 * info) - u1**2 / (1 + s2 * info1))
    assert abs(exact - limit) <= bound  # the theory's bound holds for the exact density too
    assert abs(log.loglik() - exact) <= rounding, (log.loglik() - exact)


def test_auto_prior_is_diffuse_unless_bias_std_is_given():
    scenario, logs = _small()
    assert _prepare(scenario, logs, prior="auto").prior == "diffuse"
    given, _ = _small("filter.bias_std=0.1")
    assert _prepare(given, logs, prior="auto").prior == "scenario"
    markov, _ = _small("truth.bias_correlation_time=3")
    result = _prepare(markov, logs, prior="auto").calibrate()
    assert result.bias_prior_std == markov.filter_settings.bias_std  # the stationary std, not diffuse


def test_a_changed_correlation_time_is_close_to_the_log_prepared_with_it():
    """A log prepared at tau_0 = 0 and evaluated at tau = 3 s against the exact composition at 3 s: the
    continuous-time correction leaves a relative error of order dt / tau (0.01 / 3)."""
    scenario, logs = _small("scenario.truth=discrete", "truth.bias_correlation_time=3", "truth.bias_std=0.05")
    exact = _prepare(scenario, logs)
    constant, _ = _small("scenario.truth=discrete", "truth.bias_std=0.05")
    approx = _prepare(constant, logs)
    values = {"filter.bias_correlation_time": 3.0}
    got, want = approx.loglik(values), exact.loglik()
    dt_over_tau = 0.01 / 3.0
    assert abs(got - want) <= dt_over_tau * abs(want - approx.loglik()), (got, want)
    np.testing.assert_allclose(approx.calibrate(values).bias, exact.calibrate().bias, atol=dt_over_tau * 0.05)


def test_calibrate_of_a_log_equals_calibrate_accel_gps():
    scenario, logs = _small()
    direct = calibrate_accel_gps(scenario, logs.sample_time, logs.accel[0], logs.fix_time, logs.gps_position[0], logs.gps_velocity[0])
    prepared = _prepare(scenario, logs).calibrate()
    for name in ("bias", "covariance", "residual", "innovation_cov"):
        np.testing.assert_array_equal(getattr(prepared, name), getattr(direct, name))
    # and the likelihood is the decomposition of its innovations
    _close(_prepare(scenario, logs).loglik(), innovation_loglik(direct.residual, direct.innovation_cov))


def test_settings_keys_values_and_units():
    scenario, logs = _small("filter.gps_latency=0.01")
    log = _prepare(scenario, logs)
    assert log.fixes == 20
    assert log.settings_value("filter.accel_noise_std") == scenario.filter_settings.accel_noise_std
    assert log.settings_value("filter.gps_latency") == 0.01
    assert log.unit("filter.gps_latency") == "s" and log.unit("filter.bias_std") == "m/s^2"
    with pytest.raises(ConfigError, match="filter.no_such_key"):
        log.loglik({"filter.no_such_key": 1.0})
    with pytest.raises(ConfigError, match="log.position_std_multiplier"):
        log.loglik({"log.position_std_multiplier": 2.0})  # no position_std column
    with pytest.raises(ConfigError, match="filter.accel_noise_std"):
        log.loglik({"filter.accel_noise_std": -1.0})


def _report(*extra, seed=3):
    scenario = build_scenario("accel-gps", assignments=["scenario.duration=60", *extra])
    return scenario, sample_accel_gps_logs(scenario, np.random.default_rng(seed), 1)


def test_the_gate_rejects_gross_outliers_and_keeps_the_bias():
    scenario, logs = _report()
    position = logs.gps_position[0].copy()
    bad = np.array([40, 90, 150, 220])
    position[bad] += np.array([60.0, -45.0, 80.0, -70.0])  # tens of sigma
    args = (scenario, logs.sample_time, logs.accel[0], logs.fix_time, position, logs.gps_velocity[0])
    gated = calibrate_accel_gps(*args, gate=0.999)
    np.testing.assert_array_equal(gated.rejected_rows, bad + 1)
    for form in ("standard", "sqrt"):  # the numpy loops gate alike
        other = calibrate_accel_gps(*args, gate=0.999, form=form)
        np.testing.assert_array_equal(other.rejected_rows, bad + 1)
        np.testing.assert_allclose(other.bias, gated.bias, rtol=1e-9, atol=1e-9 * gated.std[-1, 2])
    truth = logs.bias[0, -1]
    assert abs(gated.bias[-1] - truth) <= 3 * gated.std[-1, 2]
    # ungated, the outliers pull the bias (the check above has power), and gate off is the old filter
    plain = calibrate_accel_gps(*args)
    assert np.all(plain.nis[bad] > stats.chi2.ppf(0.999, 2))
    assert plain.rejected_rows.size == 0 and not plain.rejected.any()
    # and the likelihood leaves the rejected fixes out
    log = prepare_accel_gps_log(*args)
    run = log.calibrate(gate=0.999)
    kept = np.where(run.rejected[:, None], np.nan, run.residual)
    _close(log.loglik(gate=0.999), innovation_loglik(kept, run.innovation_cov))


def test_a_gate_no_fix_reaches_gives_the_ungated_numbers():
    scenario, logs = _report()
    args = (scenario, logs.sample_time, logs.accel[0], logs.fix_time, logs.gps_position[0], logs.gps_velocity[0])
    plain, wide = calibrate_accel_gps(*args), calibrate_accel_gps(*args, gate=1 - 1e-15)
    assert wide.rejected_rows.size == 0
    for name in ("bias", "covariance", "residual", "innovation_cov"):
        np.testing.assert_array_equal(getattr(wide, name), getattr(plain, name))


def _late_log(latency, seed=4):
    """The report's log with every fix stamped ``latency`` s after the time it describes."""
    scenario, logs = _report("scenario.truth=discrete", seed=seed)
    return scenario, logs, logs.fix_time + latency


def test_latency_setting_removes_the_bias_error_latency_causes():
    scenario, logs, stamps = _late_log(0.02)
    args = (logs.sample_time, logs.accel[0], stamps, logs.gps_position[0], logs.gps_velocity[0])
    truth = logs.bias[0, -1]
    ignored = calibrate_accel_gps(scenario, *args, init="first-fix")
    late, _ = _report("scenario.truth=discrete", "filter.gps_latency=0.02")
    honoured = calibrate_accel_gps(late, *args, init="first-fix")
    assert abs(ignored.bias[-1] - truth) > 4 * ignored.std[-1, 2]  # the fault is real
    assert abs(honoured.bias[-1] - truth) <= 3 * honoured.std[-1, 2]
    assert honoured.gps_latency == 0.02


def test_loglik_peaks_near_the_true_latency():
    scenario, logs, stamps = _late_log(0.02)
    log = prepare_accel_gps_log(scenario, logs.sample_time, logs.accel[0], stamps, logs.gps_position[0], logs.gps_velocity[0], init="first-fix")
    grid = np.linspace(0.0, 0.04, 41)
    values = np.array([log.loglik({"filter.gps_latency": lat}) for lat in grid])
    i = int(np.argmax(values))
    best, step = grid[i], grid[1] - grid[0]
    # within three standard errors of the estimate (the observed information, a second difference)
    curvature = -(values[i + 1] - 2 * values[i] + values[i - 1]) / step**2
    assert abs(best - 0.02) <= 3 / np.sqrt(curvature) + step, (best, 1 / np.sqrt(curvature))


def test_verify_refuses_a_filter_latency():
    scenario = build_scenario("accel-gps", assignments=["filter.gps_latency=0.02"])
    with pytest.raises(ConfigError, match="filter.gps_latency"):
        scenario.filter_model()
