"""The EKF Monte Carlo of a nonlinear model, one block fused in compiled code: truth, filter and every sum.

:func:`ekf_block` is the compiled twin of :meth:`kalcal.scenarios.nonlinear.problem.NonlinearProblem.block_sums`
for the EKF: from the block's normals (drawn by numpy exactly as the numpy path draws them, so a seed gives
the same realizations on both paths) it simulates the truth with the truth's f and h, runs the filter's EKF
(predict M = F P F^T + Q; update by the package's one compiled covariance update,
:func:`kalcal.core.kernels.covariance_update`, Joseph form), and adds each update's errors, P_k, S_k,
NEES, NIS (and their shape histograms), whitened errors and innovations, the effect sizes' sums and the Cramér–Rao bound's expectations
(F, F^T Q^-1 F at the true x_{k-1}, H^T R^-1 H at the true x_k) into the block's sums: the checks' and
the effect sizes' on the checked states (all of them, or a scenario's subset: imu-3axis's 9 parameters,
its pose's tilts nuisance states), the bound's on every state. The kernel's own state is one tile's
(P_{k-1} and P_k, (d, d) for each of its m realizations, in the thread's arena) and each update's totals,
each tile's sums reduced over its lanes into them at once; its inputs and outputs grow with K: the block's
normals (K, n, q + r) and the sums, the residual pair sums (K p)^2 among them. Memory is flat in the run's N
(blocks of at most 4,096), not in K.

Layout: the block's realizations in tiles of m, structure of arrays (realizations on the last axis, as
covariance_update takes them), tiles outer and updates inner: a tile's P_{k-1} and P_k (418 KB at
imu-3axis's d = 11 and m = 216) are used by its K updates one after another, where with updates outer
every update went through the whole block's (7.9 MB) before it came back to a tile: 7-16% of imu-3axis's
run at 2 threads in three sittings, two of them with a withdrawn change of about 1% (benchmarks/README.md;
the caches' part in it is the likely cause, not measured: the development machine gives no cache counters). Each
update's totals take the tiles' sums in tile order, the same additions either way. A last tile that is not full repeats the
block's last realization in its spare lanes (finite numbers through every step) and leaves them out of
every sum.

The model's functions arrive as arguments, printed from its sympy expressions and compiled per model
(:mod:`kalcal.core.nonlinear_codegen`): this function is inlined into a per-model driver in the generated
module, whose machine code numba caches (a kernel with function arguments is not cached itself).

It returns False, having stopped, where a measurement or its H is not finite (a missing measurement: the
numpy path's rule, a prediction only) or a P or S is not positive definite: the caller then runs the
block on the numpy path from the same draws, which gives that case's numbers (or its error).
"""

# numba cache stamp: kalcal.core.kernels a5dbbb626c1a87c1

from __future__ import annotations

import numba
import numpy as np

from kalcal.core.kernels import covariance_update, update_work


@numba.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _cholesky_lanes(a, lower, m, acc):
    """lower (q, q, m) with L L^T = a (q, q, m) lane by lane; False where a pivot is not positive.

    Each entry's loop over the lanes is innermost (it vectorizes), ``acc`` (>= m,) its running sum: per
    lane the same operations in the same order as an entry-by-entry factorization."""
    q = a.shape[0]
    for i in range(q):
        for c in range(i + 1):
            for j in range(m):
                acc[j] = a[i, c, j]
            for b in range(c):
                for j in range(m):
                    acc[j] = acc[j] - lower[i, b, j] * lower[c, b, j]
            if i == c:
                # no branch in the lane loop (it would keep the loop from vectorizing): a pivot that is
                # not positive (or NaN) gives a zero or NaN root, found below
                for j in range(m):
                    lower[i, i, j] = np.sqrt(acc[j])
            else:
                for j in range(m):
                    lower[i, c, j] = acc[j] / lower[c, c, j]
    positive = True
    for i in range(q):
        for j in range(m):
            positive = positive and lower[i, i, j] > 0.0
    return positive


@numba.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _forward_lanes(lower, v, out, m, acc):
    """out (q, m) with L out = v, lane by lane (L (q, q, m) lower triangular); the lane loops innermost."""
    q = lower.shape[0]
    for i in range(q):
        for j in range(m):
            acc[j] = v[i, j]
        for b in range(i):
            for j in range(m):
                acc[j] = acc[j] - lower[i, b, j] * out[b, j]
        for j in range(m):
            out[i, j] = acc[j] / lower[i, i, j]


# The reductions over a tile's lanes below are the kernel's only code compiled with 'reassoc': a sum
# over the lanes may be taken in whatever order vectorizes it (running sums by lane modulo the vector
# width, then added together), which LLVM does only when allowed to reassociate. Written out as 4 or 8
# running sums in plain Python, numba's loop did not vectorize (scalar: 83 ns per realization for the
# 351 products of 26 rows against 22 ns reassociated, against 59 ns for the per-lane rows they replace).
# The order stays fixed by the machine code: the same sums for the same draws on a machine, within
# rounding of any other order (the tests hold them to the numpy path's to 1e-10). Not inlined at numba's
# level, so that their flags stay theirs. The four- and eight-sum ones take the outer products' rows in
# fours: a row loaded once for four products, one call for four or eight sums (the kernel 360 -> 344 and
# 387 -> 354 ns per update per realization, best of 25-30 interleaved blocks).
@numba.njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract", "reassoc"})
def _lane_dot(a, b, m):
    """sum over j < m of a[j] * b[j] (rows of a tile's arrays): one product sum over the lanes."""
    acc = 0.0
    for j in range(m):
        acc += a[j] * b[j]
    return acc


@numba.njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract", "reassoc"})
def _lane_dot4(a, b0, b1, b2, b3, m):
    """The four product sums a . b0, ..., a . b3 over j < m in one pass: a row loaded once for four
    products (the reductions' loads, not their multiply-adds, bound them)."""
    s0 = s1 = s2 = s3 = 0.0
    for j in range(m):
        v = a[j]
        s0 += v * b0[j]
        s1 += v * b1[j]
        s2 += v * b2[j]
        s3 += v * b3[j]
    return s0, s1, s2, s3


@numba.njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract", "reassoc"})
def _lane_dot24(a0, a1, b0, b1, b2, b3, m):
    """The eight product sums a0 . b0..b3 and a1 . b0..b3 over j < m in one pass."""
    s0 = s1 = s2 = s3 = t0 = t1 = t2 = t3 = 0.0
    for j in range(m):
        u = a0[j]
        w = a1[j]
        x0 = b0[j]
        x1 = b1[j]
        x2 = b2[j]
        x3 = b3[j]
        s0 += u * x0
        s1 += u * x1
        s2 += u * x2
        s3 += u * x3
        t0 += w * x0
        t1 += w * x1
        t2 += w * x2
        t3 += w * x3
    return s0, s1, s2, s3, t0, t1, t2, t3


@numba.njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract", "reassoc"})
def _lane_sum(a, m):
    """sum over j < m of a[j]."""
    acc = 0.0
    for j in range(m):
        acc += a[j]
    return acc


@numba.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _add_lanes(out, v, m):
    """out[:m] += v[:m] (rows of the tile's arrays): one store per loop, so that the loop vectorizes."""
    for j in range(m):
        out[j] += v[j]


@numba.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _add_products(out, a, b, m):
    """out[:m] += a[:m] * b[:m], one store per loop."""
    for j in range(m):
        out[j] += a[j] * b[j]


@numba.njit(cache=True, nogil=True, inline="always")
def arena_size(d, p, dc, m):
    """float64 values of :func:`ekf_block`'s arena for d states, p measurements, dc checked states and tiles
    of m: one tile's state (the kernel takes the tiles one at a time, each through every update), per
    realization the truth's and the filter's states (2 d), P_{k-1} and P_k (2 d^2), and the statistics'
    sums over the updates (3 + 3 dc + p)."""
    return m * (2 * d * (d + 1) + 3 + 3 * dc + p)


@numba.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _add_shape_lanes(k, values, scale, histogram, where, m):
    """:func:`kalcal.montecarlo.sum_kernels.add_shape` of values[:m], its roots taken first in one lane loop
    (vectorized: a square root rounds alike in a vector), then counted: the same floor of the same product,
    the same bins (NaN in the last); ``where`` (>= m,) is scratch."""
    last = histogram.shape[1] - 1.0
    for j in range(m):
        x = values[j]
        where[j] = np.sqrt(x if x > 0.0 else 0.0) * scale
    for j in range(m):
        w = where[j]
        histogram[k, int(w if w < last else last) if values[j] == values[j] else int(last)] += 1


@numba.njit(cache=True, nogil=True, inline="always", error_model="numpy")
def ekf_block(
    ft, jac_ft, hh_t, ff, jac_ff, hh_f,
    first, noise, t_x0, t_p0f, t_qf, t_rf, t_dt, q_inv, has_q_inv, r_chol,
    f_x0, f_p0, f_q, f_r, f_dt, inputs, data, structure, sums, normalized, eff, m, arena,
):
    """One block's sums (module docstring). K updates, n realizations, d states, p measurements.

    Parameters
    ----------
    ft, jac_ft, hh_t : compiled functions
        The truth's f, F, and h with H at once (:mod:`kalcal.core.nonlinear_codegen`'s calling convention).
    ff, jac_ff, hh_f : compiled functions
        The filter's.
    first : ndarray, shape (n, d)
        The normals of x_0.
    noise : ndarray, shape (K, n, q + r)
        The normals of the process (first q) and measurement noises (r) of each update, one per column of
        ``t_qf`` and ``t_rf`` (the numpy path's draws, :func:`kalcal.scenarios.nonlinear.problem._drawn_factor`).
    t_x0, t_p0f, t_qf, t_rf : ndarray
        The truth's prior mean (d,) and square roots C C^T of P0 (d, d), Q (d, q) and R (p, r); of Q's and
        R's, only the columns that are not all zero (q and r of them).
    t_dt, f_dt : float
        The truth's and the filter's time steps (s).
    q_inv : ndarray, shape (d, d)
        The truth's Q^-1, used where ``has_q_inv`` (Q positive definite).
    r_chol : ndarray, shape (p, p)
        The truth's R's lower Cholesky factor.
    f_x0, f_p0, f_q, f_r : ndarray
        The filter's prior mean (d,), P0 (d, d), Q (d, d), R (p, p).
    inputs, data : ndarray, shapes (K, m_in), (K, k)
        Each update's input and data (zero columns where the model takes none).
    structure : tuple (ft_nz, ff_nz, ht_nz, hf_nz, checked)
        ft_nz, ff_nz (d, d) bool: where the truth's and the filter's F are not identically zero (the
        printed F writes only there, :mod:`kalcal.core.nonlinear_codegen`), ht_nz, hf_nz (p, d) bool: the
        truth's and the filter's H's: the products with the other entries, exact zeros, are skipped
        (the same sums). checked (c,) int: the states the checks and
        effect sizes are on, in the filter's order (all d of them, or a subset: the others are nuisance
        states, as a static pose's tilts); the bound's sums stay on all d.
    sums : SumBuffers
        Added into (its state axes of size c) (own P_k: the whitened sums kept); ``residuals`` (K p, n) receives the normalized
        innovations where its first axis is not empty.
    normalized : ndarray, shape (K, p)
        Sum of the normalized innovations, added into.
    eff : tuple of ndarray
        The effect sums' views (:class:`kalcal.stats.effects.EffectLayout`), in its order: nees_sq, nees_avg,
        nis_avg, e4, p2, e2p, pooled, z, z2, zbar, lag1, f, ftqf, htrh; added into.
    m : int
        The tile's width (realizations).
    arena : ndarray, shape (>= arena_size(d, p, c, m),)
        float64 room for a tile's state and per-realization sums, overwritten (its contents on entry
        are not read): the caller keeps one per thread and passes it to every block.

    Returns
    -------
    bool
        True where every update ran; False where a measurement or H was not finite or a P or S not
        positive definite (the sums are then incomplete and to be discarded).
    """
    n, d = first.shape
    n_updates = noise.shape[0]
    p = f_r.shape[0]
    t_nz, f_nz, h_nz, hf_nz, checked = structure
    dc = checked.shape[0]
    # where R^-1/2 H (the bound's whitened truth H, a forward substitution through R's factor) is not
    # identically zero: row i is H's row i and the rows w < i before it that R's factor joins to it
    w_nz = np.zeros((p, d), dtype=np.bool_)
    for i in range(p):
        for b in range(d):
            w_nz[i, b] = h_nz[i, b]
            for w in range(i):
                if r_chol[i, w] != 0.0 and w_nz[w, b]:
                    w_nz[i, b] = True
    tiles = (n + m - 1) // m
    nees_sq, nees_avg, nis_avg, e4, p2, e2p, pooled, zsum, z2sum, zbar, lag1, fsum, ftqf, htrh = eff
    keep_pairs = sums.residuals.shape[0] > 0
    # one tile's state, carved from the caller's arena (:func:`arena_size`), which a thread reuses tile
    # after tile and block after block (memory fresh from the system costs a page fault at its first touch)
    if arena.shape[0] < arena_size(d, p, dc, m):
        raise ValueError("ekf_block: the arena is smaller than arena_size(d, p, dc, m)")
    xt = arena[:m * d].reshape((d, m))
    xf = arena[m * d:2 * m * d].reshape((d, m))
    # P_{k-1} and P_k in turn (update k reads one and writes the other): the prediction reads P_{k-1}
    # while it writes M, so that a row of F with one entry needs no product F P of its own
    at = 2 * m * d
    cov = arena[at:at + m * d * d].reshape((d, d, m))
    at += m * d * d
    cov_next = arena[at:at + m * d * d].reshape((d, d, m))
    # the statistics' per-realization sums over the updates (from zero at each tile's start)
    at += m * d * d
    stats = arena[at:at + m * (3 + 3 * dc + p)]
    r_nees = stats[:m]
    r_nis = stats[m:2 * m]
    r_lag = stats[2 * m:3 * m]
    at = 3 * m
    r_a = stats[at:at + m * dc].reshape((dc, m))
    at += m * dc
    r_b = stats[at:at + m * dc].reshape((dc, m))
    at += m * dc
    r_z = stats[at:at + m * dc].reshape((dc, m))
    at += m * dc
    last_u = stats[at:at + m * p].reshape((p, m))
    # the columns of each row of the truth's noise factors that are not zero, in order
    nq, nr = t_qf.shape[1], t_rf.shape[1]
    q_cols = np.zeros((d, nq), dtype=np.int64)
    q_count = np.zeros(d, dtype=np.int64)
    for a in range(d):
        for b in range(nq):
            if t_qf[a, b] != 0.0:
                q_cols[a, q_count[a]] = b
                q_count[a] += 1
    r_cols = np.zeros((p, nr), dtype=np.int64)
    r_count = np.zeros(p, dtype=np.int64)
    for a in range(p):
        for b in range(nr):
            if t_rf[a, b] != 0.0:
                r_cols[a, r_count[a]] = b
                r_count[a] += 1
    # each row of the filter's F: its entries that are not identically zero, their columns in order
    f_cols = np.zeros((d, d), dtype=np.int64)
    f_count = np.zeros(d, dtype=np.int64)
    for a in range(d):
        for b in range(d):
            if f_nz[a, b]:
                f_cols[a, f_count[a]] = b
                f_count[a] += 1
    # one tile's scratch (the Jacobians' zeros from the start: the printed F and H write only the others)
    tmp = np.empty((d, m))
    jf = np.zeros((d, d, m))
    g = np.empty((d, d, m))
    zt = np.empty((p, m))
    hz = np.empty((p, m))
    jh = np.zeros((p, d, m))
    wh = np.zeros((p, d, m))
    big_f = np.zeros((d, d, m))
    fc = np.empty((d, d, m))
    xbar = np.empty((d, m))
    big_h = np.zeros((p, d, m))
    res = np.empty((p, m))
    gain = np.empty((p, d, m))
    s = np.empty((p, p, m))
    work = update_work(d, p, m)
    work.h_nz[:, :] = hf_nz  # the covariance update skips the filter's H's identically zero entries
    # M's pattern: M_ab = Q_ab + sum F_aw P_ww' F_bw' is identically zero where Q_ab is zero and row a or b
    # of F has no entry (a renewed state: no covariance with any other where Q gives it none); and the
    # states whose entries of P anything reads after the update: the next prediction reads P's entries
    # of F's columns that are not identically zero (and f reads those states of x alone), the statistics
    # the checked states'. H M skips M's zeros, the update computes K's rows and P's entries of those
    # states alone (P's others keep M's values, never read)
    for a in range(d):
        work.keep[a] = False
        for b in range(d):
            if f_nz[b, a]:
                work.keep[a] = True
            work.m_nz[a, b] = f_q[a, b] != 0.0 or f_q[b, a] != 0.0 or (f_count[a] > 0 and f_count[b] > 0)
    for a in range(dc):
        work.keep[checked[a]] = True
    cc = np.empty((dc, dc, m))  # the checked states' block of P, their estimate
    xc = np.empty((dc, m))
    lp = np.empty((dc, dc, m))
    ls = np.empty((p, p, m))
    e = np.empty((dc, m))
    eps = np.empty((dc, m))
    u = np.empty((p, m))
    row = np.empty(m)  # a running sum per lane
    zrow = np.empty((2, m))  # e / sqrt(P_ii) and e^2 of one state
    zero_row = np.zeros(m)
    tile_nees = np.empty(m)  # the tile's NEES and NIS, binned into the shape histograms
    tile_nis = np.empty(m)
    # one update's sums, each tile's reduced over its lanes into them: the offsets of each (the checks'
    # on the c checked states, the bound's on all d)
    cd, dd, pp = dc * dc, d * d, p * p
    o_err = 0
    o_eo = o_err + dc
    o_est = o_eo + cd
    o_esto = o_est + dc
    o_ee = o_esto + cd
    o_nees = o_ee + cd
    o_nis = o_nees + 1
    o_res = o_nis + 1
    o_reso = o_res + p
    o_fc = o_reso + pp
    o_we = o_fc + cd
    o_wo = o_we + dc
    o_wx = o_wo + cd
    o_nr = o_wx + cd
    o_nsq = o_nr + p
    o_e4 = o_nsq + 1
    o_p2 = o_e4 + dc
    o_e2p = o_p2 + dc
    o_z = o_e2p + dc
    o_z2 = o_z + dc
    o_f = o_z2 + dc
    o_ftqf = o_f + dd
    o_htrh = o_ftqf + dd
    width = o_htrh + dd
    # tiles outer, updates inner: a tile's state (its P_{k-1} and P_k: 418 KB at d = 11) is used by its K
    # updates one after another (module docstring); each update's sums are reduced into that update's row of
    # totals, tile after tile in order (the same additions as with updates outer)
    upd = np.zeros((n_updates, width))
    for t in range(tiles):
        # the tile's realizations: x_0 drawn, the filter's prior, the per-realization sums from zero
        for j in range(m):
            col = min(t * m + j, n - 1)
            for a in range(d):
                acc = 0.0
                for b in range(d):
                    acc += first[col, b] * t_p0f[a, b]
                xt[a, j] = t_x0[a] + acc
                xf[a, j] = f_x0[a]
                for b in range(d):
                    cov[a, b, j] = f_p0[a, b]
        stats[:] = 0.0
        mt = min(m, n - t * m)
        for k in range(n_updates):
            uk = inputs[k]
            dk = data[k]
            tot = upd[k]
            x = xt
            xh = xf
            last = cov if k % 2 == 0 else cov_next  # P_{k-1}
            c = cov_next if k % 2 == 0 else cov  # M, then P_k
            # the truth: F at x_{k-1} (the bound's), then x_k = f(x_{k-1}) + C_Q w, z_k = h(x_k) + C_R v
            for j in range(m):
                jac_ft(x, uk, t_dt, jf, j)
                ft(x, uk, t_dt, tmp, j)
            # (the noise factors' zero entries skipped: a kept state's, as a static parameter's, has a zero
            # row; the draws are finite, so a skipped product is an exact zero)
            for j in range(m):
                col = min(t * m + j, n - 1)
                for a in range(d):
                    acc = 0.0
                    for i in range(q_count[a]):
                        b = q_cols[a, i]
                        acc += noise[k, col, b] * t_qf[a, b]
                    x[a, j] = tmp[a, j] + acc
            for j in range(m):
                hh_t(x, dk, hz, jh, j)
            for j in range(m):
                col = min(t * m + j, n - 1)
                for a in range(p):
                    acc = 0.0
                    for i in range(r_count[a]):
                        b = r_cols[a, i]
                        acc += noise[k, col, nq + b] * t_rf[a, b]
                    zt[a, j] = hz[a, j] + acc
            # the filter's prediction: xbar = f(xhat), M = F P F^T + Q (symmetrized), from P_{k-1} (last)
            # into c, only the products with F's entries that are not identically zero: a renewed state's
            # row of F has none (its rows of M are Q's), a kept state's one 1, and a row of one entry
            # F_aw gives (F P)_a = F_aw P_w (inline below); F P is formed for the rows of more entries
            for j in range(m):
                jac_ff(xh, uk, f_dt, big_f, j)
                ff(xh, uk, f_dt, xbar, j)
            for a in range(d):
                if f_count[a] > 1:
                    for b in range(d):
                        w = f_cols[a, 0]
                        for j in range(m):
                            fc[a, b, j] = big_f[a, w, j] * last[w, b, j]
                        for i in range(1, f_count[a]):
                            w = f_cols[a, i]
                            for j in range(m):
                                fc[a, b, j] += big_f[a, w, j] * last[w, b, j]
            for a in range(d):
                wa = f_cols[a, 0]
                for b in range(a + 1):
                    q_ab = 0.5 * (f_q[a, b] + f_q[b, a])
                    if f_count[a] == 1 and f_count[b] == 1:  # (the first product in the same pass)
                        w = f_cols[b, 0]
                        for j in range(m):
                            c[a, b, j] = q_ab + big_f[a, wa, j] * last[wa, w, j] * big_f[b, w, j]
                        continue_at = 1
                    else:
                        for j in range(m):
                            c[a, b, j] = q_ab
                        continue_at = 0
                    if f_count[a] == 1:
                        for i in range(continue_at, f_count[b]):
                            w = f_cols[b, i]
                            for j in range(m):
                                c[a, b, j] += big_f[a, wa, j] * last[wa, w, j] * big_f[b, w, j]
                    elif f_count[a] > 1:
                        for i in range(f_count[b]):
                            w = f_cols[b, i]
                            for j in range(m):
                                c[a, b, j] += fc[a, w, j] * big_f[b, w, j]
                    for j in range(m):
                        c[b, a, j] = c[a, b, j]
            # the update: H at xbar, r = z - h(xbar), then the one compiled covariance update (Joseph)
            for j in range(m):
                hh_f(xbar, dk, hz, big_h, j)
            for a in range(p):
                for j in range(m):
                    res[a, j] = zt[a, j] - hz[a, j]
            # a non-finite innovation or H entry (the printed H's identically zero entries are exact
            # zeros) makes its lane's sum of x * 0 NaN: one vectorized pass, then one test per lane
            for j in range(mt):
                row[j] = 0.0
            for a in range(p):
                _add_products(row, res[a], zero_row, mt)
                for b in range(d):
                    if hf_nz[a, b]:
                        _add_products(row, big_h[a, b], zero_row, mt)
            for j in range(mt):
                if row[j] != 0.0:
                    return False
            covariance_update(c, big_h, f_r, True, gain, s, work)
            # (a state that is not kept, which neither f nor the statistics read, stays at its prediction:
            # the update computed no row of K for it)
            for a in range(d):
                for j in range(m):
                    xh[a, j] = xbar[a, j]
                if work.keep[a]:
                    for i in range(p):
                        _add_products(xh[a], gain[i, a], res[i], m)
            # the statistics on the checked states: e = x - xhat, eps = L_P^-1 e, u = L_S^-1 r, each
            # realization's own factors (of P's checked block)
            # (each lane loop below stores into one array row: a loop that stores into several rows of
            # arrays that may overlap needs more runtime overlap checks than LLVM makes, and runs unvectorized)
            for a in range(dc):
                ca = checked[a]
                for j in range(m):
                    e[a, j] = x[ca, j] - xh[ca, j]
                for j in range(m):
                    xc[a, j] = xh[ca, j]
                for b in range(a + 1):  # (the lower triangle: the factor and the sums read no other)
                    cb = checked[b]
                    for j in range(m):
                        cc[a, b, j] = c[ca, cb, j]
            if not _cholesky_lanes(cc, lp, mt, row):
                return False
            if not _cholesky_lanes(s, ls, mt, row):
                return False
            _forward_lanes(lp, e, eps, mt, row)
            _forward_lanes(ls, res, u, mt, row)
            # the update's sums on the checked states, each reduced over the tile's lanes at once (products
            # of rows in the cache) into its one total: the symmetric ones' lower triangles (their upper
            # ones the same numbers, mirrored at the update's end)
            # (four or eight sums a pass where the columns come in fours: each row loaded once for them)
            for a in range(dc):
                tot[o_err + a] += _lane_sum(e[a], mt)
                tot[o_est + a] += _lane_sum(xc[a], mt)
                tot[o_we + a] += _lane_sum(eps[a], mt)
                b = 0
                while b + 4 <= dc:
                    ab = a * dc + b
                    s0, s1, s2, s3, t0, t1, t2, t3 = _lane_dot24(e[a], eps[a], xc[b], xc[b + 1], xc[b + 2], xc[b + 3], mt)
                    tot[o_ee + ab] += s0
                    tot[o_ee + ab + 1] += s1
                    tot[o_ee + ab + 2] += s2
                    tot[o_ee + ab + 3] += s3
                    tot[o_wx + ab] += t0
                    tot[o_wx + ab + 1] += t1
                    tot[o_wx + ab + 2] += t2
                    tot[o_wx + ab + 3] += t3
                    b += 4
                for b in range(b, dc):
                    ab = a * dc + b
                    tot[o_ee + ab] += _lane_dot(e[a], xc[b], mt)
                    tot[o_wx + ab] += _lane_dot(eps[a], xc[b], mt)
                b = 0
                while b + 4 <= a + 1:
                    ab = a * dc + b
                    s0, s1, s2, s3 = _lane_dot4(e[a], e[b], e[b + 1], e[b + 2], e[b + 3], mt)
                    tot[o_eo + ab] += s0
                    tot[o_eo + ab + 1] += s1
                    tot[o_eo + ab + 2] += s2
                    tot[o_eo + ab + 3] += s3
                    s0, s1, s2, s3 = _lane_dot4(xc[a], xc[b], xc[b + 1], xc[b + 2], xc[b + 3], mt)
                    tot[o_esto + ab] += s0
                    tot[o_esto + ab + 1] += s1
                    tot[o_esto + ab + 2] += s2
                    tot[o_esto + ab + 3] += s3
                    s0, s1, s2, s3 = _lane_dot4(eps[a], eps[b], eps[b + 1], eps[b + 2], eps[b + 3], mt)
                    tot[o_wo + ab] += s0
                    tot[o_wo + ab + 1] += s1
                    tot[o_wo + ab + 2] += s2
                    tot[o_wo + ab + 3] += s3
                    b += 4
                for b in range(b, a + 1):
                    ab = a * dc + b
                    tot[o_eo + ab] += _lane_dot(e[a], e[b], mt)
                    tot[o_esto + ab] += _lane_dot(xc[a], xc[b], mt)
                    tot[o_wo + ab] += _lane_dot(eps[a], eps[b], mt)
                for b in range(a + 1):
                    tot[o_fc + a * dc + b] += _lane_sum(cc[a, b], mt)
            for j in range(mt):
                tile_nees[j] = 0.0
            for a in range(dc):
                _add_products(tile_nees, eps[a], eps[a], mt)
            for j in range(mt):
                tile_nis[j] = 0.0
            for a in range(p):
                _add_products(tile_nis, u[a], u[a], mt)
            if k > 0:
                for a in range(p):
                    _add_products(r_lag, last_u[a], u[a], mt)
            for a in range(p):
                for j in range(mt):
                    last_u[a, j] = u[a, j]
            tot[o_nees] += _lane_sum(tile_nees, mt)
            tot[o_nis] += _lane_sum(tile_nis, mt)
            tot[o_nsq] += _lane_dot(tile_nees, tile_nees, mt)
            _add_lanes(r_nees, tile_nees, mt)
            _add_lanes(r_nis, tile_nis, mt)
            # the shape check's histograms, by the fixed-gain kernels' binning (the same floor of the same
            # product as numpy's shape_histogram)
            _add_shape_lanes(k, tile_nees, sums.nees_grid.scale, sums.nees_histogram, zrow[0], mt)
            _add_shape_lanes(k, tile_nis, sums.nis_grid.scale, sums.nis_histogram, zrow[0], mt)
            for a in range(p):
                tot[o_res + a] += _lane_sum(res[a], mt)
                tot[o_nr + a] += _lane_sum(u[a], mt)
                for b in range(a + 1):
                    tot[o_reso + a * p + b] += _lane_dot(res[a], res[b], mt)
            if keep_pairs:
                for a in range(p):
                    for j in range(mt):
                        sums.residuals[k * p + a, t * m + j] = u[a, j]
            for a in range(dc):
                for j in range(mt):
                    zrow[0, j] = e[a, j] / np.sqrt(cc[a, a, j])  # e / sqrt(P_ii)
                for j in range(mt):
                    zrow[1, j] = e[a, j] * e[a, j]
                tot[o_e4 + a] += _lane_dot(zrow[1], zrow[1], mt)
                tot[o_p2 + a] += _lane_dot(cc[a, a], cc[a, a], mt)
                tot[o_e2p + a] += _lane_dot(zrow[1], cc[a, a], mt)
                tot[o_z + a] += _lane_sum(zrow[0], mt)
                tot[o_z2 + a] += _lane_dot(zrow[0], zrow[0], mt)
                _add_lanes(r_a[a], zrow[1], mt)
                _add_lanes(r_b[a], cc[a, a], mt)
                _add_lanes(r_z[a], zrow[0], mt)
            # the Cramér–Rao bound's expectations at the truth's states: F, F^T Q^-1 F, (R^-1/2 H)^T (R^-1/2 H)
            for a in range(d):
                for b in range(d):
                    if t_nz[a, b]:
                        tot[o_f + a * d + b] += _lane_sum(jf[a, b], mt)
            if has_q_inv:
                for a in range(d):
                    for b in range(d):
                        for j in range(mt):
                            g[a, b, j] = 0.0
                        for w in range(d):
                            if t_nz[w, b]:
                                for j in range(mt):
                                    g[a, b, j] += q_inv[a, w] * jf[w, b, j]
                for a in range(d):
                    for b in range(d):
                        for w in range(d):
                            if t_nz[w, a]:
                                tot[o_ftqf + a * d + b] += _lane_dot(jf[w, a], g[w, b], mt)
            diagonal_r = True
            for i in range(p):
                for w in range(i):
                    diagonal_r = diagonal_r and r_chol[i, w] == 0.0
            if diagonal_r:
                # R diagonal: (R^-1/2 H)_ia = H_ia / R_ii^(1/2), so each update's sum of products is
                # H's over the lanes divided by R_ii once (not every lane by R_ii^(1/2))
                for i in range(p):
                    r_ii = r_chol[i, i] * r_chol[i, i]
                    for a in range(d):
                        if w_nz[i, a]:
                            for b in range(a + 1):
                                if w_nz[i, b]:
                                    tot[o_htrh + a * d + b] += _lane_dot(jh[i, a], jh[i, b], mt) / r_ii
            for i in range(p if not diagonal_r else 0):  # R^-1/2 H by forward substitution, the lane
                for b in range(d):  # loops innermost; its identically zero entries stay zeros
                    if w_nz[i, b]:
                        for j in range(mt):
                            row[j] = jh[i, b, j]
                        for w in range(i):
                            for j in range(mt):
                                row[j] = row[j] - r_chol[i, w] * wh[w, b, j]
                        for j in range(mt):
                            wh[i, b, j] = row[j] / r_chol[i, i]
            for a in range(d if not diagonal_r else 0):  # symmetric: the lower triangle, mirrored
                for b in range(a + 1):  # below; the products with R^-1/2 H's zero entries skipped
                    for i in range(p):
                        if w_nz[i, a] and w_nz[i, b]:
                            tot[o_htrh + a * d + b] += _lane_dot(wh[i, a], wh[i, b], mt)
        # the per-realization averages over the updates (EffectAccumulator.finish)
        for j in range(mt):
            avg = r_nees[j] / n_updates
            nees_avg[0] += avg
            nees_avg[1] += avg * avg
            avg = r_nis[j] / n_updates
            nis_avg[0] += avg
            nis_avg[1] += avg * avg
            for a in range(dc):
                ra, rb = r_a[a, j], r_b[a, j]
                pooled[0, a] += ra
                pooled[1, a] += rb
                pooled[2, a] += ra * ra
                pooled[3, a] += rb * rb
                pooled[4, a] += ra * rb
                zb = r_z[a, j] / n_updates
                zbar[0, a] += zb
                zbar[1, a] += zb * zb
            if n_updates > 1:
                lag = r_lag[j] / ((n_updates - 1) * p)
                lag1[0] += lag
                lag1[1] += lag * lag
    for k in range(n_updates):
        tot = upd[k]
        # the update's sums (the symmetric ones from their lower triangles)
        for a in range(dc):
            sums.error[k, a] += tot[o_err + a]
            sums.estimate[k, a] += tot[o_est + a]
            sums.whitened_error[k, a] += tot[o_we + a]
            e4[k, a] += tot[o_e4 + a]
            p2[k, a] += tot[o_p2 + a]
            e2p[k, a] += tot[o_e2p + a]
            zsum[k, a] += tot[o_z + a]
            z2sum[k, a] += tot[o_z2 + a]
            for b in range(dc):
                ab = a * dc + b
                low = max(a, b) * dc + min(a, b)
                sums.error_outer[k, a, b] += tot[o_eo + low]
                sums.estimate_outer[k, a, b] += tot[o_esto + low]
                sums.error_estimate[k, a, b] += tot[o_ee + ab]
                sums.filter_cov[k, a, b] += tot[o_fc + low]
                sums.whitened_outer[k, a, b] += tot[o_wo + low]
                sums.whitened_estimate[k, a, b] += tot[o_wx + ab]
        for a in range(d):
            for b in range(d):
                ab = a * d + b
                fsum[k, a, b] += tot[o_f + ab]
                ftqf[k, a, b] += tot[o_ftqf + ab]
                htrh[k, a, b] += tot[o_htrh + max(a, b) * d + min(a, b)]
        sums.nees[k] += tot[o_nees]
        sums.nis[k] += tot[o_nis]
        nees_sq[k] += tot[o_nsq]
        for a in range(p):
            sums.residual[k, a] += tot[o_res + a]
            normalized[k, a] += tot[o_nr + a]
            for b in range(p):
                sums.residual_own[k, a, b] += tot[o_reso + max(a, b) * p + min(a, b)]
    return True
