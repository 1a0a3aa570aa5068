"""Per-sample sensor streams of the accelerometer/GPS scenario, as the report simulates them.

Random numbers are drawn in one fixed order so that a log and the Monte Carlo's sampled engine see the
same realizations for the same generator state:

1. ``(n, 4)``: standard normals for p0, v0, b and the noise of accelerometer sample 0 (``(n, 5)`` with a
   scale-factor error s last);
2. for each GPS interval k = 0..K-1, ``(n, m + p)``: the noise of samples k m + 1 .. (k + 1) m, then the
   noise of each component fix k measures, p = 2 (position, velocity) or, with ``scenario.gps_fixes =
   "velocity"``, p = 1 (velocity alone: no position noise is drawn), then, with Student-t fixes
   (``truth.gps_noise = "student-t"``), nu more per component (the columns m + p + a nu ..., whose squares
   sum to its chi-square(nu): :func:`~kalcal.simulation.exact.student_t_noise`); and, when the bias has noise of its own (a random walk or
   Gauss-Markov), ``(n, m)`` more: the bias noise of steps k m .. (k + 1) m - 1;
3. only in a log with GNSS outliers (``truth.gps_outlier_rate`` and ``gps_outlier_std`` > 0), after all
   the above: ``(n, K)`` uniforms (fix k is an outlier when its uniform is below the rate), then ``(n, K)``
   normals, the gross errors in units of ``gps_outlier_std``, added to the outliers' positions.

``truth.gps_latency`` moves no draw: the fixes' stamps are the times they describe plus the latency.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kalcal.scenarios.accel_gps.mechanization import integrate, interval_weights
from kalcal.scenarios.accel_gps.settings import AccelGpsScenario
from kalcal.simulation.exact import student_t_noise


def fix_noise(scenario: AccelGpsScenario, draw: np.ndarray, p: int) -> np.ndarray:
    """The unit-variance noise of an interval's fixes, (n, p), from its draws' columns after the m samples
    (n, p) or, Student t, (n, p (1 + nu))."""
    nu = scenario.truth.gps_measurement_dof
    return student_t_noise(draw, p, nu) if nu else draw


@dataclass(frozen=True)
class AccelGpsLogs:
    """n realizations of the recorded streams. J + 1 accelerometer samples, K fixes."""

    sample_time: np.ndarray  #: t_j, s, (J + 1,)
    accel: np.ndarray  #: measured a_c(t_j), m/s^2, (n, J + 1)
    true_accel: np.ndarray  #: a(t_j), m/s^2, (J + 1,)
    position: np.ndarray  #: true p(t_j), m, (n, J + 1)
    velocity: np.ndarray  #: true v(t_j), m/s, (n, J + 1)
    bias: np.ndarray  #: true b at every sample, m/s^2, (n, J + 1) (constant unless it drifts)
    scale: np.ndarray  #: true scale-factor error s, dimensionless, (n,) (zero without one)
    fix_index: np.ndarray  #: sample index of each fix, (K,)
    gps_position: np.ndarray  #: m, (n, K); NaN with velocity-only fixes (the receiver reports none)
    gps_velocity: np.ndarray  #: m/s, (n, K)
    gps_outlier_error: np.ndarray | None = None  #: gross error in each fix's position, m, 0 if none, (n, K)
    gps_latency: float = 0.0  #: the fixes' stamp minus the time they describe, s

    @property
    def fix_time(self) -> np.ndarray:
        """Times the fixes describe, s, (K,)."""
        return self.sample_time[self.fix_index]

    @property
    def fix_stamp(self) -> np.ndarray:
        """The fixes' time stamps as logged, fix_time + gps_latency, s, (K,)."""
        return self.fix_time + self.gps_latency

    @property
    def gps_outlier(self) -> np.ndarray:
        """Which fixes carry a gross error, bool (n, K)."""
        if self.gps_outlier_error is None:
            return np.zeros(self.gps_position.shape, dtype=bool)
        return self.gps_outlier_error != 0


def initial_draws(scenario: AccelGpsScenario, rng: np.random.Generator, n: int):
    """p0, v0, b, the noise of sample 0 and the scale-factor error s (drawn only in a scale scenario)."""
    t = scenario.truth
    xi = rng.standard_normal((n, 5 if scenario.has_scale else 4))
    p0 = t.position0_mean + t.position0_std * xi[:, 0]
    v0 = t.velocity0_mean + t.velocity0_std * xi[:, 1]
    bias = t.bias_std * xi[:, 2]
    scale = t.scale_std * xi[:, 4] if scenario.has_scale else np.zeros(n)
    return p0, v0, bias, t.accel_noise_std * xi[:, 3], scale


def _bias_path(scenario: AccelGpsScenario, start: np.ndarray, draw: np.ndarray | None) -> np.ndarray:
    """The bias at the m + 1 samples of an interval, (n, m + 1), from its value at the first (n,).

    b_{j+1} = phi_b b_j + sqrt(q_b) xi_j; ``draw`` (n, m) holds the xi, None when the bias is constant
    (then the result is (n, 1), which broadcasts over the interval).
    """
    if draw is None:
        return start[:, None]
    t, dt = scenario.truth, scenario.scenario.sample_period
    decay = t.bias_decay(dt)
    from scipy.signal import lfilter  # 1.4 s to import: only the numpy sampler's drifting bias needs it

    path = lfilter([1.0], [1.0, -decay], np.sqrt(t.bias_step_variance(dt)) * draw, axis=1, zi=decay * start[:, None])[0]
    return np.concatenate([start[:, None], path], axis=1)


def _bias_draw(scenario: AccelGpsScenario, rng: np.random.Generator, n: int, m: int) -> np.ndarray | None:
    dt = scenario.scenario.sample_period
    return rng.standard_normal((n, m)) if scenario.truth.bias_step_variance(dt) > 0 else None


def deterministic_motion(scenario: AccelGpsScenario, times: np.ndarray, sample_accel: np.ndarray) -> np.ndarray:
    """Position and velocity due to a(t) alone, from rest at the origin, at ``times`` (m, m/s), (len, 2).

    ``analytic`` truth: the closed form. ``discrete`` truth: ``sample_accel`` (a(t_j) at every sample up to
    the last of ``times``) integrated with the scenario's own scheme.
    """
    settings = scenario.scenario
    if settings.truth == "analytic":
        return np.stack(scenario.analytic_motion(times), axis=-1)
    position, velocity = integrate(sample_accel, settings.sample_period, 0.0, 0.0, settings.integration)
    index = np.rint(np.asarray(times) / settings.sample_period).astype(int)
    return np.stack([position[index], velocity[index]], axis=-1)


def sample_accel_gps_logs(scenario: AccelGpsScenario, rng: np.random.Generator, n: int = 1) -> AccelGpsLogs:
    """Draw n realizations of the full accelerometer and GPS logs.

    Memory is n (J + 1) doubles per stream: meant for writing logs, not for large ensembles.
    """
    s, t = scenario.scenario, scenario.truth
    m, n_updates = s.steps_per_update, s.n_updates
    times = s.sample_times()
    p0, v0, bias0, noise0, scale = initial_draws(scenario, rng, n)
    noise = np.empty((n, s.n_samples + 1))
    noise[:, 0] = noise0
    bias = np.empty((n, s.n_samples + 1))
    bias[:, 0] = bias0
    rows = scenario.fix_states
    gps_noise = np.full((n, n_updates, 2), np.nan)  # a component the receiver does not report stays NaN
    fix_draws = len(rows) * (1 + t.gps_measurement_dof)
    for k in range(n_updates):
        draw = rng.standard_normal((n, m + fix_draws))
        noise[:, k * m + 1 : (k + 1) * m + 1] = t.accel_noise_std * draw[:, :m]
        gps_noise[:, k, list(rows)] = fix_noise(scenario, draw[:, m:], len(rows))
        bias[:, k * m : (k + 1) * m + 1] = _bias_path(scenario, bias[:, k * m], _bias_draw(scenario, rng, n, m))
    true_accel = scenario.true_accel(times)
    motion = deterministic_motion(scenario, times, true_accel)
    position = p0[:, None] + v0[:, None] * times + motion[:, 0]
    velocity = v0[:, None] + motion[:, 1] + np.zeros((n, 1))
    fix_index = np.arange(1, n_updates + 1) * m
    gps_position = position[:, fix_index] + t.gps_position_std * gps_noise[:, :, 0]
    outlier_error = None
    if t.gps_outlier_rate > 0 and t.gps_outlier_std > 0:
        hit = rng.random((n, n_updates)) < t.gps_outlier_rate
        outlier_error = np.where(hit, t.gps_outlier_std * rng.standard_normal((n, n_updates)), 0.0)
        gps_position = gps_position + outlier_error
    return AccelGpsLogs(
        sample_time=times,
        accel=(1.0 + scale[:, None]) * true_accel + bias + noise,
        true_accel=true_accel,
        position=position,
        velocity=velocity,
        bias=bias,
        scale=scale,
        fix_index=fix_index,
        gps_position=gps_position,
        gps_velocity=velocity[:, fix_index] + t.gps_velocity_std * gps_noise[:, :, 1],
        gps_outlier_error=outlier_error,
        gps_latency=t.gps_latency,
    )


def sample_accel_gps_errors(
    scenario: AccelGpsScenario, rng: np.random.Generator, n: int
) -> tuple[np.ndarray, np.ndarray]:
    """The error states and error measurements at every fix, simulated sample by sample.

    Same draws as :func:`sample_accel_gps_logs`, streamed one GPS interval at a time so that memory is
    O(n m), not O(n J). Each interval integrates its m accelerometer samples with the scenario's scheme
    (written as the linear map of :func:`~kalcal.scenarios.accel_gps.mechanization.interval_weights`).

    Returns
    -------
    states : ndarray, shape (n, K, d)
        dx = [p - p_c, v - v_c, b] at each fix (and s, with a scale-factor error).
    measurements : ndarray, shape (n, K, p)
        dz = [gps_position - p_c, gps_velocity - v_c] at each fix (p = 2), or [gps_velocity - v_c] with
        velocity-only fixes (p = 1).
    """
    s, t = scenario.scenario, scenario.truth
    m, n_updates, dt = s.steps_per_update, s.n_updates, s.sample_period
    interval = m * dt
    weights = interval_weights(s.integration, dt, m)  # (m + 1, 2)
    times = s.sample_times()
    true_accel = scenario.true_accel(times)
    fix_times = s.update_times()
    motion = deterministic_motion(scenario, fix_times, true_accel)
    p0, v0, bias_now, noise, scale = initial_draws(scenario, rng, n)
    d = 4 if scenario.has_scale else 3
    pc0, vc0 = scenario.nominal_start()
    nominal = np.empty((n, 2))
    nominal[:, 0], nominal[:, 1] = pc0, vc0
    states = np.empty((n, n_updates, d))
    rows = list(scenario.fix_states)
    measurements = np.empty((n, n_updates, len(rows)))
    block = np.empty((n, m + 1))
    block[:, 0] = noise
    gps_std = scenario.fix_stds(t)
    fix_draws = len(rows) * (1 + t.gps_measurement_dof)
    for k in range(n_updates):
        draw = rng.standard_normal((n, m + fix_draws))
        block[:, 1:] = t.accel_noise_std * draw[:, :m]
        bias = _bias_path(scenario, bias_now, _bias_draw(scenario, rng, n, m))
        bias_now = bias[:, -1]
        measured = block + (1.0 + scale[:, None]) * true_accel[k * m : (k + 1) * m + 1] + bias
        # p_c(t + T) = p_c(t) + v_c(t) T + sum_i C_i,p a_i;   v_c(t + T) = v_c(t) + sum_i C_i,v a_i
        increment = measured @ weights
        nominal[:, 0] += nominal[:, 1] * interval + increment[:, 0]
        nominal[:, 1] += increment[:, 1]
        states[:, k, 0] = p0 + v0 * fix_times[k] + motion[k, 0] - nominal[:, 0]
        states[:, k, 1] = v0 + motion[k, 1] - nominal[:, 1]
        states[:, k, 2] = bias_now
        if d == 4:
            states[:, k, 3] = scale
        measurements[:, k] = states[:, k, rows] + gps_std * fix_noise(scenario, draw[:, m:], len(rows))
        block[:, 0] = block[:, m]
    return states, measurements
