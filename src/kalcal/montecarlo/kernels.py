"""The fixed-gain filter's block kernels: sample (or take) the truth, filter it and sum, in one compiled pass.

numpy spends its time here on many passes over small arrays: one realization-step costs about seventy
multiply-adds spread over some thirty array operations, each with its own temporary. These kernels make
the same passes inside one compiled function, with the realizations as the innermost, contiguous axis
(structure of arrays: a state is (d, n), a draw (q, n)), so that every inner loop vectorizes and nothing
leaves the cache; each update's sums go through :func:`kalcal.montecarlo.sum_kernels.accumulate`. The
exact kernel draws each update's standard normals from the block's generator as it reaches the update
(:func:`standard_normals`, numpy's values in numpy's order), so that the draws, 600 normals a
realization, are read from the cache instead of written to memory and read back; with the pairs kept,
the innovations are formed in their rows of the block's residual buffer, not copied there.
``benchmarks/bench_montecarlo.py`` measures the factor against the numpy reference path
(``sample_exact`` + ``run_with_gains`` + ``MomentSums.from_block``), which stays as the tests' oracle:
both consume the same draws and agree to rounding.
"""

# numba cache stamp: kalcal.montecarlo.sum_kernels 1ed5637ca40b0768

from __future__ import annotations

import numba
import numpy as np

from kalcal.montecarlo.sum_kernels import FAST, accumulate, add_shape, affine, whitened_squares


@numba.njit(nogil=True, cache=True)
def standard_normals(rng, out):
    """Fill ``out`` (q, n) with rng's next q n standard normals, in C order: the values and the generator
    state that ``out[...] = rng.standard_normal((q, n))`` leaves (numba's Generator runs numpy's ziggurat
    on the same bit generator, and this function is compiled without fast-math, so that no contraction
    changes an acceptance test)."""
    for a in range(out.shape[0]):
        for i in range(out.shape[1]):
            out[a, i] = rng.standard_normal()


@numba.njit(nogil=True, cache=True, fastmath=FAST)
def _filter_and_accumulate(k, truth, z, x, xbar, residual, phi, h, gains, sums, whiteners, scratch):
    """One update of the fixed-gain filter for every realization, then the moment sums at update k.

    whiteners: (W_P (K, d, d), W_S (K, p, p), c_e (K, d), c_r (K, p)), W^T W the inverse of the shared P_k
    and S_k, c the predicted means of the error and the innovation (the model error; zero without one),
    about which each realization's NEES and NIS are binned; scratch:
    (values (n,), work (d, n), work (p, n)), where each realization's NEES and NIS are formed for the
    shape histograms (the only per-realization use of them: their sums follow from the second moments).

    truth (d, n): states, overwritten with the errors; z (p, n): measurements; x (d, n): posterior,
    updated in place; residual (p, n): where the innovations are formed when the pairs are not kept (with
    them, they are formed in their rows of ``sums.residuals``, not copied there); sums: the block's
    :class:`~kalcal.montecarlo.accumulators.SumBuffers` (its NEES, NIS and P sums are left to the caller:
    every realization shares P_k and S_k).
    """
    d, n = x.shape
    p = z.shape[0]
    keep = sums.residuals.shape[0] > 0
    residual = sums.residuals[k * p:(k + 1) * p] if keep else residual[:]
    affine(xbar, phi, x, False)  # xbar = Phi x
    for a in range(p):  # r = z - H xbar
        for i in range(n):
            residual[a, i] = z[a, i]
    affine(residual, -h, xbar, True)
    for a in range(d):  # x = xbar + K r
        for i in range(n):
            x[a, i] = xbar[a, i]
    affine(x, gains[k], residual, True)
    for a in range(d):  # truth becomes the error e = x_true - xhat
        for i in range(n):
            truth[a, i] -= x[a, i]
    shared = np.empty(0)
    accumulate(k, 0, truth, x, residual, shared, shared, np.empty((0, 0, 0)), np.empty((0, n)), sums, not keep)
    values, state_work, innovation_work = scratch
    whitened_squares(values, whiteners[0][k], truth, whiteners[2][k], state_work)
    add_shape(k, values, sums.nees_grid.scale, sums.nees_histogram)
    whitened_squares(values, whiteners[1][k], residual, whiteners[3][k], innovation_work)
    add_shape(k, values, sums.nis_grid.scale, sums.nis_histogram)


@numba.njit(nogil=True, cache=True)
def _filter_buffers(x0, p, n):
    """The filter's posterior (d, n), started at x0 in every realization, and its prior and innovation
    buffers (d, n) and (p, n)."""
    d = x0.shape[0]
    x = np.empty((d, n))
    for a in range(d):
        x[a, :] = x0[a]
    return x, np.empty((d, n)), np.empty((p, n))


@numba.njit(nogil=True, cache=True, fastmath=FAST)
def student_t(draws, p, dof):
    """Rows 0 .. p - 1 of ``draws`` (p (1 + dof), n) made unit-variance Student t(dof) in place: row a times
    sqrt((dof - 2) / chi2_a), chi2_a the sum of squares of rows p + a dof .. p + (a + 1) dof - 1
    (:func:`kalcal.simulation.exact.student_t_noise`)."""
    n = draws.shape[1]
    for a in range(p):
        for i in range(n):
            chi2 = 0.0
            for j in range(dof):
                w = draws[p + a * dof + j, i]
                chi2 += w * w
            draws[a, i] *= np.sqrt((dof - 2) / chi2)


@numba.njit(nogil=True, cache=True)
def _shape_scratch(d, p, n):
    """The scratch of :func:`_filter_and_accumulate`'s per-realization NEES and NIS: (n,), (d, n), (p, n)."""
    return np.empty(n), np.empty((d, n)), np.empty((p, n))


@numba.njit(nogil=True, cache=True, fastmath=FAST)
def exact_block_moments(
    y0, u0, rng, transitions, noise, boundary_in, model_error, h_truth, measure,
    phis, h, gains, x0, state_whiteners, innovation_whiteners, error_centers, residual_centers, sums, error_map,
    traced, trace, dof,
):
    """Sample the exact update-rate truth (:mod:`kalcal.simulation.exact`) and filter it, in one pass.

    y0 (d, n) truth at sample 0; u0 (c, n) its opening boundary sample; rng: the block's generator, past
    the draws of y0 and u0, from which update k's (r + c + p, n) standard normals are drawn in turn
    (:func:`standard_normals`: the values and order of ``rng.standard_normal((K, r + c + p, n))``);
    transitions (K, d, d) of the truth over each interval; noise (d, r + c) = [L | b_out]; boundary_in
    (d, c); model_error (K, d); h_truth (p, d); measure (p, p) = G. Filter: phis (K, d_f, d_f) over each
    interval, h (p, d_f), gains (K, d_f, p), x0 (d_f,), state_whiteners (K, d_f, d_f) and
    innovation_whiteners (K, p, p) with W^T W = P_k^-1 and S_k^-1, error_centers (K, d_f) and
    residual_centers (K, p) the predicted means (each realization's NEES and NIS about them for the shape
    histograms). sums: the block's
    :class:`~kalcal.montecarlo.accumulators.SumBuffers` (in the filter's d_f), added to. error_map
    (d_f, d): M of a truth with states of its own, whose error is e = M x - xhat; (0, 0) for a truth
    over the filter's states (d_f = d, e = x - xhat, with no product: that path is the one without a map).
    traced: a realization of the block (0 <= traced < n) whose error and estimate at every update are
    copied into trace (2, K, d_f) as they are formed; -1 (and trace (0, 0, 0)) for none. dof: the
    truth's ``measurement_dof`` (0: Gaussian; else each update draws p dof more normals after its p
    measurement normals, :func:`student_t`).
    """
    d, n = y0.shape
    mapped = error_map.shape[0] > 0
    mapped_state = np.empty((error_map.shape[0], n))
    n_updates = transitions.shape[0]
    rc = noise.shape[1]
    c = boundary_in.shape[1]
    r = rc - c
    p = h.shape[0]
    noise_rows = p * (1 + dof)
    y = y0.copy()
    y_next = np.empty((d, n))
    state = np.empty((d, n))
    z = np.empty((p, n))
    step = np.empty((rc + noise_rows, n))  # this update's draws
    previous = np.empty((rc + noise_rows if c else 0, n))  # the last update's (its closing boundary samples)
    x, xbar, residual = _filter_buffers(x0, p, n)
    scratch = _shape_scratch(x0.shape[0], p, n)
    whiteners = (state_whiteners, innovation_whiteners, error_centers, residual_centers)
    for k in range(n_updates):
        standard_normals(rng, step)
        affine(y_next, transitions[k], y, False)
        affine(y_next, noise, step[:rc], True)
        if c:
            affine(y_next, boundary_in, u0 if k == 0 else previous[r:rc], True)
        y, y_next = y_next, y
        for a in range(d):
            shift = model_error[k, a]
            for i in range(n):
                state[a, i] = y[a, i] + shift
        affine(z, h_truth, state, False)
        if dof:
            student_t(step[rc:], p, dof)
        affine(z, measure, step[rc:rc + p], True)
        if mapped:
            affine(mapped_state, error_map, state, False)  # the filter's states of the truth: M x
        errors = mapped_state if mapped else state
        _filter_and_accumulate(k, errors, z, x, xbar, residual, phis[k], h, gains, sums, whiteners, scratch)
        if traced >= 0:
            for a in range(x.shape[0]):
                trace[0, k, a] = errors[a, traced]
                trace[1, k, a] = x[a, traced]
        if c:
            step, previous = previous, step


@numba.njit(nogil=True, cache=True, fastmath=FAST)
def filter_block_moments(
    states, measurements, phis, h, gains, x0, state_whiteners, innovation_whiteners, error_centers, residual_centers, sums
):
    """Filter given truths and accumulate, for a sampler without a compiled block of its own (the sampled
    engine has one: :func:`kalcal.scenarios.accel_gps.sampled_kernels.sampled_block_moments`).

    states (K, d, n) (overwritten with the errors), measurements (K, p, n); the rest as in
    :func:`exact_block_moments`.
    """
    n_updates, d, n = states.shape
    x, xbar, residual = _filter_buffers(x0, h.shape[0], n)
    scratch = _shape_scratch(d, h.shape[0], n)
    whiteners = (state_whiteners, innovation_whiteners, error_centers, residual_centers)
    for k in range(n_updates):
        _filter_and_accumulate(
            k, states[k], measurements[k], x, xbar, residual, phis[k], h, gains, sums, whiteners, scratch
        )
