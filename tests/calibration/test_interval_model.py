"""The compiled composition of an interval's pieces against the numpy reference predict of covariances.

Oracles: :func:`kalcal.core.steps.predict_covariance` applied piece by piece (Q <- T Q T^T + G G^T from
Q = 0, Phi <- T Phi from I), :func:`kalcal.core.steps.interval_transition` where every piece is the
same sample step, and the same recursion in plain Python floats; composing in chunks against composing
in one pass, bit for bit.
"""

from __future__ import annotations

import tracemalloc
from dataclasses import replace

import numpy as np
import pytest

from kalcal.scenarios.accel_gps.interval_model import (
    SOURCES,
    _accumulate_by_source,
    composed_sources,
    interval_sources,
)
from kalcal.core.steps import interval_transition, predict_covariance
from kalcal.linalg import symmetrize
from kalcal.scenarios import build_scenario


def _one_pass(phis, inputs, owner, n_intervals):
    """Every piece composed in one compiled pass: Phi_k (K, 3, 3) and Q_k^(r) (R, K, 3, 3), a source per
    column of ``inputs`` (N, 3, R)."""
    out_phi = np.broadcast_to(np.eye(3), (n_intervals, 3, 3)).copy()
    out_q = np.zeros((inputs.shape[2], n_intervals, 3, 3))
    _accumulate_by_source(phis, np.ascontiguousarray(inputs), np.asarray(owner, dtype=np.int64), out_phi, out_q)
    return out_phi, symmetrize(out_q)


def _reference(phis, inputs, owner, n_intervals):
    out_phi = np.broadcast_to(np.eye(3), (n_intervals, 3, 3)).copy()
    out_q = np.zeros((n_intervals, 3, 3))
    for t, g, k in zip(phis, inputs, owner):
        out_q[k] = predict_covariance(out_q[k], t, g @ g.T)
        out_phi[k] = t @ out_phi[k]
    return out_phi, out_q


@pytest.mark.parametrize("n_sources", [1, 2])
def test_composition_equals_reference_predicts_on_random_pieces(n_sources):
    rng = np.random.default_rng(41)
    n_intervals = 9
    # 0 to 6 pieces per interval, intervals 2 and 5 with none (I, 0)
    counts = rng.integers(1, 7, n_intervals)
    counts[[2, 5]] = 0
    owner = np.repeat(np.arange(n_intervals), counts)
    phis = np.eye(3) + 0.3 * rng.standard_normal((owner.size, 3, 3))
    inputs = rng.standard_normal((owner.size, 3, n_sources))
    phi_k, q_k = _one_pass(phis, inputs, owner, n_intervals)
    for r in range(n_sources):
        ref_phi, ref_q = _reference(phis, inputs[:, :, r : r + 1], owner, n_intervals)
        np.testing.assert_allclose(phi_k, ref_phi, rtol=1e-12, atol=1e-13 * np.abs(ref_phi).max())
        np.testing.assert_allclose(q_k[r], ref_q, rtol=1e-12, atol=1e-13 * np.abs(ref_q).max())
        np.testing.assert_array_equal(q_k[r], np.swapaxes(q_k[r], 1, 2))
    np.testing.assert_array_equal(phi_k[[2, 5]], np.broadcast_to(np.eye(3), (2, 3, 3)))
    np.testing.assert_array_equal(q_k[:, [2, 5]], 0.0)


def test_composition_of_equal_steps_is_interval_transition():
    """Two sources, the columns of G = Gamma chol(W), sum to the interval's Q of the sample-step model."""
    rng = np.random.default_rng(7)
    phi = np.eye(3) + 0.1 * rng.standard_normal((3, 3))
    gamma = rng.standard_normal((3, 2))
    w = np.diag([0.5, 2.0])
    steps, n_intervals = 8, 3
    owner = np.repeat(np.arange(n_intervals), steps)
    g = gamma @ np.linalg.cholesky(w)
    pieces = np.broadcast_to(phi, (owner.size, 3, 3)).copy()
    phi_k, q_k = _one_pass(pieces, np.broadcast_to(g, (owner.size, 3, 2)), owner, n_intervals)
    phi_m, q_m = interval_transition(phi, gamma, w, steps)
    for k in range(n_intervals):
        np.testing.assert_allclose(phi_k[k], phi_m, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(q_k[:, k].sum(axis=0), q_m, rtol=1e-12, atol=1e-13 * np.abs(q_m).max())


def _log_pieces(samples: int, fixes: int, seed: int = 3, on_samples: int = 0):
    """An irregular accelerometer log's pieces between cuts (its samples and fixes), as the calibration
    prepares them: (imu_time, steps, cuts, owner, fixes); ``on_samples`` of the fixes fall on samples."""
    rng = np.random.default_rng(seed)
    imu_time = np.concatenate([[0.0], np.cumsum(rng.uniform(0.004, 0.006, samples - 1))])
    fix_times = rng.uniform(imu_time[3], imu_time[-3], fixes - on_samples)
    on = rng.choice(imu_time[3:-3], on_samples, replace=False)
    fix_times = np.unique(np.concatenate([fix_times, on]))
    start = 0.5 * (imu_time[1] + imu_time[2])  # inside a step, as a first fix is
    samples_in = imu_time[(imu_time > start) & (imu_time < fix_times[-1])]
    cuts = np.union1d(np.concatenate([[start], samples_in]), fix_times)
    owner = np.searchsorted(fix_times, cuts[1:], side="left")
    return imu_time, np.diff(imu_time), cuts, owner, fix_times.size


_FILTER = build_scenario("accel-gps", None, []).filter_settings
#: a constant (or random-walk) bias, whose Gauss-Markov source is 0, and a Gauss-Markov bias (every
#: source): the sources are composed at unit variance, so only the correlation time changes them
_SETTINGS = {"constant": _FILTER, "markov": replace(_FILTER, bias_walk_std=1e-4, bias_correlation_time=40.0)}


def _python_by_source(phis, inputs, owner, n_intervals):
    """The composition in plain Python floats, IEEE double like the kernel (no numba): for each piece,
    Phi <- T Phi, and for each source Q <- T Q T^T + g g^T, then each Q's off-diagonal pairs averaged."""
    phi = [np.eye(3).tolist() for _ in range(n_intervals)]
    q = [[np.zeros((3, 3)).tolist() for _ in range(n_intervals)] for _ in range(inputs.shape[2])]
    for t, g_all, k in zip(phis.tolist(), inputs.tolist(), owner.tolist()):
        p = phi[k]
        phi[k] = [[t[a][0] * p[0][b] + t[a][1] * p[1][b] + t[a][2] * p[2][b] for b in range(3)] for a in range(3)]
        for r in range(len(q)):
            old = q[r][k]
            tq = [[t[a][0] * old[0][b] + t[a][1] * old[1][b] + t[a][2] * old[2][b] for b in range(3)] for a in range(3)]
            q[r][k] = [
                [tq[a][0] * t[b][0] + tq[a][1] * t[b][1] + tq[a][2] * t[b][2] + g_all[a][r] * g_all[b][r] for b in range(3)]
                for a in range(3)
            ]
    out_q = np.array(q)
    return np.array(phi), 0.5 * (out_q + np.swapaxes(out_q, -1, -2))


@pytest.mark.parametrize("model", sorted(_SETTINGS))
@pytest.mark.parametrize("scheme", ["trapezoid", "euler"])
@pytest.mark.parametrize("chunk", [1, 7, 256, 10**9])
def test_composed_sources_in_chunks_is_every_piece_at_once_bit_for_bit(model, scheme, chunk):
    """Chunks of pieces compose into the same bits as all pieces in one compiled pass, and into the
    plain-Python composition to rounding; some fixes fall on samples."""
    imu_time, steps, cuts, owner, fixes = _log_pieces(2000, 37, on_samples=9)
    settings = _SETTINGS[model]
    phis, inputs = interval_sources(imu_time, steps, cuts, settings, 0.005, scheme)
    used = [r for r in range(len(SOURCES)) if np.any(inputs[:, :, r] != 0.0)]
    assert used == {"constant": [0, 1], "markov": [0, 1, 2]}[model]  # the sources the model has
    expected_phi, expected_q = _one_pass(phis, inputs, owner, fixes)
    phi_k, q_k = composed_sources(imu_time, steps, cuts, owner, fixes, settings, 0.005, scheme, chunk=chunk)
    assert q_k.shape == (len(SOURCES), fixes, 3, 3)
    np.testing.assert_array_equal(phi_k, expected_phi)
    np.testing.assert_array_equal(q_k, expected_q)
    np.testing.assert_array_equal(q_k, np.swapaxes(q_k, -1, -2))
    if chunk == 7:  # the oracle once per model and scheme (it is slow)
        ref_phi, ref_q = _python_by_source(phis, inputs, owner, fixes)
        np.testing.assert_allclose(phi_k, ref_phi, rtol=1e-13, atol=1e-15)
        for r in range(len(SOURCES)):  # each source at its own scale (the bias walk's is 1e4 times the others')
            np.testing.assert_allclose(q_k[r], ref_q[r], rtol=1e-12, atol=1e-13 * np.abs(ref_q[r]).max())


def test_composed_sources_refuses_what_its_kernel_would_not_check():
    """A chunk below 1 (or not a whole number), and an owner array of the wrong length, type or range,
    are refused before the compiled pass, which does not check its indices."""
    imu_time, steps, cuts, owner, fixes = _log_pieces(100, 5)
    args = (imu_time, steps, cuts)
    settings = (_SETTINGS["markov"], 0.005, "trapezoid")
    for chunk in (0, -3, 2.5, True):
        with pytest.raises(ValueError, match="chunk"):
            composed_sources(*args, owner, fixes, *settings, chunk=chunk)
    with pytest.raises(ValueError, match="one interval per piece"):
        composed_sources(*args, owner[:-1], fixes, *settings)
    with pytest.raises(ValueError, match=r"must lie in \[0, 4\)"):
        composed_sources(*args, owner, fixes - 1, *settings)
    with pytest.raises(ValueError, match="must lie in"):
        composed_sources(*args, owner - 1, fixes, *settings)
    with pytest.raises(ValueError, match="whole interval numbers"):
        composed_sources(*args, owner + 0.5, fixes, *settings)


def test_composed_sources_of_no_pieces_and_of_an_interval_without_pieces_are_identity_and_zero():
    imu_time, steps, cuts, owner, fixes = _log_pieces(100, 5)
    settings = (_SETTINGS["markov"], 0.005, "trapezoid")
    phi_k, q_k = composed_sources(imu_time, steps, cuts[:1], owner[:0], 3, *settings)
    np.testing.assert_array_equal(phi_k, np.broadcast_to(np.eye(3), (3, 3, 3)))
    np.testing.assert_array_equal(q_k, 0.0)
    shifted = np.where(owner >= 2, owner + 1, owner)  # interval 2 gets no piece
    phi_k, q_k = composed_sources(imu_time, steps, cuts, shifted, fixes + 1, *settings, chunk=3)
    np.testing.assert_array_equal(phi_k[2], np.eye(3))
    np.testing.assert_array_equal(q_k[:, 2], 0.0)
    assert all(np.any(q_k[0, k] != 0.0) for k in (0, 1, 3))  # the intervals with pieces


def _peak_bytes(samples: int, chunk: int) -> int:
    """Peak of numpy's allocations (traced) during one composition beyond what was allocated before it,
    bytes; a trace already running (``-X tracemalloc``) is kept running."""
    imu_time, steps, cuts, owner, fixes = _log_pieces(samples, 40)
    args = (imu_time, steps, cuts, owner, fixes, _SETTINGS["markov"], 0.005, "trapezoid")
    composed_sources(*args, chunk=chunk)  # compiled
    started = not tracemalloc.is_tracing()
    if started:
        tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        before = tracemalloc.get_traced_memory()[0]
        composed_sources(*args, chunk=chunk)
        return tracemalloc.get_traced_memory()[1] - before
    finally:
        if started:
            tracemalloc.stop()


def test_composed_sources_memory_does_not_grow_with_the_pieces():
    """At the same number of fixes (the output, 288 bytes a fix), the composition's peak memory is that of
    a chunk however many pieces there are: 8 times the samples stays within 1.25x; one chunk of all
    pieces (what it would be without chunks) grows with them, by more than 4x."""
    small, large = _peak_bytes(4096, 1024), _peak_bytes(8 * 4096, 1024)
    assert small > 1024 * 100  # a chunk's arrays were traced (numpy reports its buffers to tracemalloc)
    assert large < 1.25 * small
    assert _peak_bytes(8 * 4096, 10**9) > 4 * _peak_bytes(4096, 10**9)
