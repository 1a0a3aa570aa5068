"""The fixed-gain block kernel over a log: per-update noise factor, rows and measurement factor, in one compiled pass.

:func:`kalcal.montecarlo.kernels.exact_block_moments` with L_k, H_k and G_k (and the filter's H_k) taken
per update, and no shared boundary sample or model error (a model file's truth over a log has neither):
the same draws in the same order (:func:`~kalcal.montecarlo.kernels.standard_normals`), the same filter
step and sums (:func:`~kalcal.montecarlo.kernels._filter_and_accumulate`), so that a log whose rows are
constant gives the time-invariant kernel's sums to rounding (tests/models/test_model_file_logged.py).
"""

# numba cache stamp: kalcal.montecarlo.kernels daec5e09513f4163, kalcal.montecarlo.sum_kernels 1ed5637ca40b0768

from __future__ import annotations

import numba
import numpy as np

from kalcal.montecarlo.kernels import _filter_and_accumulate, _filter_buffers, _shape_scratch, standard_normals
from kalcal.montecarlo.sum_kernels import FAST, affine


@numba.njit(nogil=True, cache=True, fastmath=FAST)
def logged_block_moments(
    y0, rng, transitions, noise, h_truth, measure, phis, h, gains, x0,
    state_whiteners, innovation_whiteners, error_centers, residual_centers, sums, error_map, traced, trace,
):
    """Sample the update-rate truth over a log, filter it with fixed gains and sum, in one pass.

    y0 (n_t, n): the truth at row 0; rng: the block's generator past y0's draws, from which update k's
    (r + p, n) standard normals are drawn in turn; transitions (K, n_t, n_t), noise L_k (K, n_t, r),
    h_truth (K, p, n_t), measure G_k (K, p, p). Filter: phis (K, d, d), h (K, p, d), gains (K, d, p),
    x0 (d,); the whiteners of P_k and S_k and the predicted means of e_k and r_k, about which each
    realization's NEES and NIS are binned for the shape check. sums, error_map, traced and trace as in
    :func:`kalcal.montecarlo.kernels.exact_block_moments`.
    """
    d_t, n = y0.shape
    mapped = error_map.shape[0] > 0
    mapped_state = np.empty((error_map.shape[0], n))
    n_updates, _, r = noise.shape
    p = h.shape[1]
    y = y0.copy()
    y_next = np.empty((d_t, n))
    z = np.empty((p, n))
    step = np.empty((r + p, n))
    x, xbar, residual = _filter_buffers(x0, p, n)
    scratch = _shape_scratch(x0.shape[0], p, n)
    whiteners = (state_whiteners, innovation_whiteners, error_centers, residual_centers)
    for k in range(n_updates):
        standard_normals(rng, step)
        affine(y_next, transitions[k], y, False)
        affine(y_next, noise[k], step[:r], True)
        y, y_next = y_next, y
        affine(z, h_truth[k], y, False)
        affine(z, measure[k], step[r:], True)
        if mapped:
            affine(mapped_state, error_map, y, False)
            errors = mapped_state
        else:
            # the kernel overwrites its truth with the errors: the state carried on must stay the truth's
            for a in range(d_t):
                for i in range(n):
                    y_next[a, i] = y[a, i]
            errors = y_next
        _filter_and_accumulate(k, errors, z, x, xbar, residual, phis[k], h[k], gains, sums, whiteners, scratch)
        if traced >= 0:
            for a in range(x.shape[0]):
                trace[0, k, a] = errors[a, traced]
                trace[1, k, a] = x[a, traced]
