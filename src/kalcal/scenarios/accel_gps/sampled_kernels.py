"""The sampled engine's block kernel: simulate every accelerometer sample, filter and sum, in one compiled pass.

:func:`kalcal.scenarios.accel_gps.sampled.sample_accel_gps_errors` (numpy) makes some fifteen passes over each GPS
interval's (n, m + p) draws: scaling, the measured samples, their integration as a matrix product, the
error states and the fixes, each with its own temporary. :func:`sampled_block_moments` draws the same
normals from the block's generator in the same order (:mod:`kalcal.scenarios.accel_gps.sampled`'s stream: the
interval's (n, m + p) samples and fix noises, then its (n, m) bias-noise draws when the bias drifts,
through :func:`~kalcal.montecarlo.kernels.standard_normals`, so that realization i's draws and the
generator's final state are numpy's), integrates each realization's samples as it reads them, and hands
the interval's error states and measurements, structure of arrays, to the fixed-gain filter step and
the moment sums of :mod:`kalcal.montecarlo.kernels`. The draws of one interval (1.4 MB for a block of
4096) stay in the cache.

It covers every truth the sampled engine simulates (a constant, random-walk or Gauss-Markov bias, with
or without a scale-factor error; either integration scheme; analytic or discrete truth). The numpy path
stays the tests' oracle: the sums agree to rounding, not bit for bit, because numpy integrates an
interval as one BLAS matrix product, whose order of additions this kernel does not reproduce.
"""

# numba cache stamp: kalcal.montecarlo.kernels daec5e09513f4163

from __future__ import annotations

import numba
import numpy as np

from kalcal.scenarios.accel_gps.mechanization import interval_weights
from kalcal.scenarios.accel_gps.settings import AccelGpsScenario
from kalcal.montecarlo.accumulators import SumBuffers
from kalcal.montecarlo.kernels import _filter_and_accumulate, _filter_buffers, _shape_scratch, standard_normals
from kalcal.montecarlo.sum_kernels import FAST
from kalcal.scenarios.accel_gps.sampled import deterministic_motion, initial_draws


@numba.njit(nogil=True, cache=True, fastmath=FAST)
def _integrate_interval(k, samples, walk_draws, carry, bias, scale, nominal, true_accel, weights, accel_std,
                        decay, walk, interval):
    """Integrate interval k's m + 1 measured samples of every realization into the nominal, in place.

    samples (n, m + p): this interval's draws (samples k m + 1 .. (k + 1) m, then the fix noises);
    walk_draws (n, m) the bias noise, or (0, 0) for a constant bias; carry (n,) the noise of sample k m,
    left as that of sample (k + 1) m; bias (n,) b at sample k m, left at (k + 1) m; scale (n,) s;
    nominal (2, n) p_c, v_c at the interval's start, left at its end; true_accel (J + 1,) a(t_j);
    weights (m + 1, 2) of :func:`~kalcal.scenarios.accel_gps.mechanization.interval_weights`; accel_std, m/s^2;
    b_{j+1} = decay b_j + walk xi_j; interval m dt, s.
    """
    n = samples.shape[0]
    m = weights.shape[0] - 1
    drifts = walk_draws.shape[0] > 0
    base = k * m
    for i in range(n):
        gain = 1.0 + scale[i]
        b = bias[i]
        noise = carry[i]
        sample = noise + gain * true_accel[base] + b
        step_p = sample * weights[0, 0]
        step_v = sample * weights[0, 1]
        for j in range(1, m + 1):
            if drifts:
                b = decay * b + walk * walk_draws[i, j - 1]
            noise = accel_std * samples[i, j - 1]
            sample = noise + gain * true_accel[base + j] + b
            step_p += sample * weights[j, 0]
            step_v += sample * weights[j, 1]
        carry[i] = noise
        bias[i] = b
        # p_c(t + T) = p_c(t) + v_c(t) T + sum_j C_j,p a_j;   v_c(t + T) = v_c(t) + sum_j C_j,v a_j
        nominal[0, i] += nominal[1, i] * interval + step_p
        nominal[1, i] += step_v


@numba.njit(nogil=True, cache=True, fastmath=FAST)
def sampled_block_moments(
    rng, p0, v0, bias0, noise0, scale, true_accel, weights, fix_times, motion, nominal0, accel_std, gps_std,
    decay, walk, drifts, interval, phis, h, gains, x0, state_whiteners, innovation_whiteners, error_centers,
    residual_centers, sums, fix_states, dof,
):
    """Simulate the accelerometer/GPS truth sample by sample and filter it, in one pass.

    rng: the block's generator, past the initial draws (:func:`~kalcal.scenarios.accel_gps.sampled.initial_draws`),
    which give p0, v0, bias0 (b at sample 0), noise0 (sample 0's noise) and scale (s, zero without
    one), each (n,); true_accel (J + 1,) m/s^2; weights (m + 1, 2); fix_times (K,) s; motion (K, 2) the
    deterministic position and velocity at each fix; nominal0 (2,) p_c(0), v_c(0); accel_std m/s^2;
    fix_states (p,) the state each fix component measures ([0, 1], or [1] for velocity alone) and
    gps_std (p,) its noise's 1-sigma (m or m/s), drawn after the interval's m samples; the bias b_{j+1} = decay b_j + walk xi_j, with its draws only when ``drifts``;
    interval m dt, s.
    The error states are [p - p_c, v - v_c, b] (and s when the filter has d = 4 states). Filter: phis
    (K, d, d), h (p, d), gains (K, d, p), x0 (d,), state_whiteners (K, d, d) and innovation_whiteners
    (K, p, p), error_centers (K, d), residual_centers (K, p)
    (:func:`~kalcal.montecarlo.kernels.exact_block_moments`'); sums: the block's
    :class:`~kalcal.montecarlo.accumulators.SumBuffers`, added to. dof: nu of Student-t fixes (0: Gaussian),
    whose p nu more normals follow the fix noises in each interval's draws.
    """
    n = p0.shape[0]
    n_updates = fix_times.shape[0]
    m = weights.shape[0] - 1
    d = x0.shape[0]
    p = h.shape[0]
    samples = np.empty((n, m + p * (1 + dof)))
    walk_draws = np.empty((n, m) if drifts else (0, 0))
    carry = noise0.copy()
    bias = bias0.copy()
    nominal = np.empty((2, n))
    for i in range(n):
        nominal[0, i] = nominal0[0]
        nominal[1, i] = nominal0[1]
    state = np.empty((d, n))
    z = np.empty((p, n))
    x, xbar, residual = _filter_buffers(x0, p, n)
    scratch = _shape_scratch(d, p, n)
    whiteners = (state_whiteners, innovation_whiteners, error_centers, residual_centers)
    for k in range(n_updates):
        standard_normals(rng, samples)
        if drifts:
            standard_normals(rng, walk_draws)
        _integrate_interval(k, samples, walk_draws, carry, bias, scale, nominal, true_accel, weights,
                            accel_std, decay, walk, interval)
        for i in range(n):
            state[0, i] = p0[i] + v0[i] * fix_times[k] + motion[k, 0] - nominal[0, i]
            state[1, i] = v0[i] + motion[k, 1] - nominal[1, i]
            state[2, i] = bias[i]
            for r in range(p):
                noise = samples[i, m + r]
                if dof:  # unit-variance Student t: w sqrt((nu - 2) / chi2), chi2 from the nu normals after the p
                    chi2 = 0.0
                    for j in range(dof):
                        w = samples[i, m + p + r * dof + j]
                        chi2 += w * w
                    noise *= np.sqrt((dof - 2) / chi2)
                z[r, i] = state[fix_states[r], i] + gps_std[r] * noise
        if d == 4:
            for i in range(n):
                state[3, i] = scale[i]
        _filter_and_accumulate(k, state, z, x, xbar, residual, phis[k], h, gains, sums, whiteners, scratch)


def accel_gps_block_sums(scenario: AccelGpsScenario, rng: np.random.Generator, n: int, phis: np.ndarray,
                         h: np.ndarray, gains: np.ndarray, x0: np.ndarray, state_whiteners: np.ndarray,
                         innovation_whiteners: np.ndarray, error_centers: np.ndarray, residual_centers: np.ndarray,
                         sums: SumBuffers) -> None:
    """Add n sampled realizations of ``scenario`` into ``sums`` through :func:`sampled_block_moments`.

    Consumes ``rng`` exactly as :func:`~kalcal.scenarios.accel_gps.sampled.sample_accel_gps_errors` does (same
    draws, same order, same final state). phis (K, d, d), h (p, d), gains (K, d, p), x0 (d,): the filter;
    state_whiteners (K, d, d), innovation_whiteners (K, p, p): W^T W = P_k^-1, S_k^-1; error_centers (K, d),
    residual_centers (K, p): the predicted means the shape histograms' NEES and NIS are taken about.
    """
    s, t = scenario.scenario, scenario.truth
    dt = s.sample_period
    p0, v0, bias0, noise0, scale = initial_draws(scenario, rng, n)
    true_accel = scenario.true_accel(s.sample_times())
    fix_times = s.update_times()
    walk_variance = t.bias_step_variance(dt)
    sampled_block_moments(
        rng, p0, v0, bias0, noise0, np.ascontiguousarray(scale), true_accel,
        np.ascontiguousarray(interval_weights(s.integration, dt, s.steps_per_update)),
        fix_times, np.ascontiguousarray(deterministic_motion(scenario, fix_times, true_accel)),
        np.array(scenario.nominal_start(), dtype=float), t.accel_noise_std,
        scenario.fix_stds(t), t.bias_decay(dt), float(np.sqrt(walk_variance)),
        walk_variance > 0, s.steps_per_update * dt, phis, h, gains, x0, state_whiteners, innovation_whiteners,
        error_centers, residual_centers, sums,
        np.array(scenario.fix_states, dtype=np.int64), t.gps_measurement_dof,
    )
