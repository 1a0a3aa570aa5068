"""The compiled composition of an interval's pieces against the numpy reference predict of covariances.

Oracle: :func:`kalcal.filters.steps.predict_covariance` applied piece by piece (Q <- T Q T^T + G G^T from
Q = 0, Phi <- T Phi from I), and :func:`kalcal.filters.steps.interval_transition` where every piece is the
same sample step.
"""

from __future__ import annotations

import tracemalloc
from dataclasses import replace

import numpy as np
import pytest

from kalcal.calibration.interval_model import SOURCES, compose_intervals, composed_sources, interval_sources
from kalcal.filters.steps import interval_transition, predict_covariance
from kalcal.models.registry import build_scenario


def _reference(phis, inputs, owner, n_intervals):
    out_phi = np.broadcast_to(np.eye(3), (n_intervals, 3, 3)).copy()
    out_q = np.zeros((n_intervals, 3, 3))
    for t, g, k in zip(phis, inputs, owner):
        out_q[k] = predict_covariance(out_q[k], t, g @ g.T)
        out_phi[k] = t @ out_phi[k]
    return out_phi, out_q


@pytest.mark.parametrize("n_inputs", [1, 2])
def test_compose_intervals_equals_reference_predicts_on_random_pieces(n_inputs):
    rng = np.random.default_rng(41)
    n_intervals = 9
    # 0 to 6 pieces per interval, intervals 2 and 5 with none (I, 0)
    counts = rng.integers(1, 7, n_intervals)
    counts[[2, 5]] = 0
    owner = np.repeat(np.arange(n_intervals), counts)
    phis = np.eye(3) + 0.3 * rng.standard_normal((owner.size, 3, 3))
    inputs = rng.standard_normal((owner.size, 3, n_inputs))
    phi_k, q_k = compose_intervals(phis, inputs, owner, n_intervals)
    ref_phi, ref_q = _reference(phis, inputs, owner, n_intervals)
    scale = np.abs(ref_q).max()
    np.testing.assert_allclose(phi_k, ref_phi, rtol=1e-12, atol=1e-13 * np.abs(ref_phi).max())
    np.testing.assert_allclose(q_k, ref_q, rtol=1e-12, atol=1e-13 * scale)
    np.testing.assert_array_equal(q_k, np.swapaxes(q_k, 1, 2))
    np.testing.assert_array_equal(phi_k[[2, 5]], np.broadcast_to(np.eye(3), (2, 3, 3)))
    np.testing.assert_array_equal(q_k[[2, 5]], 0.0)


def test_compose_intervals_of_equal_steps_is_interval_transition():
    rng = np.random.default_rng(7)
    phi = np.eye(3) + 0.1 * rng.standard_normal((3, 3))
    gamma = rng.standard_normal((3, 2))
    w = np.diag([0.5, 2.0])
    steps, n_intervals = 8, 3
    owner = np.repeat(np.arange(n_intervals), steps)
    g = gamma @ np.linalg.cholesky(w)
    phi_k, q_k = compose_intervals(
        np.broadcast_to(phi, (owner.size, 3, 3)).copy(), np.broadcast_to(g, (owner.size, 3, 2)).copy(), owner, n_intervals
    )
    phi_m, q_m = interval_transition(phi, gamma, w, steps)
    for k in range(n_intervals):
        np.testing.assert_allclose(phi_k[k], phi_m, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(q_k[k], q_m, rtol=1e-12, atol=1e-13 * np.abs(q_m).max())


def _log_pieces(samples: int, fixes: int, seed: int = 3):
    """An irregular accelerometer log's pieces between cuts (its samples and fixes), as the calibration
    prepares them: (imu_time, steps, cuts, owner, fixes)."""
    rng = np.random.default_rng(seed)
    imu_time = np.concatenate([[0.0], np.cumsum(rng.uniform(0.004, 0.006, samples - 1))])
    fix_times = np.sort(rng.uniform(imu_time[3], imu_time[-3], fixes))
    start = 0.5 * (imu_time[1] + imu_time[2])  # inside a step, as a first fix is
    samples_in = imu_time[(imu_time > start) & (imu_time < fix_times[-1])]
    cuts = np.union1d(np.concatenate([[start], samples_in]), fix_times)
    owner = np.searchsorted(fix_times, cuts[1:], side="left")
    return imu_time, np.diff(imu_time), cuts, owner, fixes


#: a filter with every noise source: the accelerometer's, a random walk and a Gauss-Markov bias
_SETTINGS = replace(build_scenario("accel-gps", None, []).filter_settings, bias_walk_std=1e-4, bias_correlation_time=40.0)


@pytest.mark.parametrize("scheme", ["trapezoid", "euler"])
@pytest.mark.parametrize("chunk", [1, 7, 256, 10**9])
def test_composed_sources_in_chunks_is_every_piece_at_once_bit_for_bit(scheme, chunk):
    """Chunks of pieces compose into the same bits as all pieces in one pass, source by source."""
    imu_time, steps, cuts, owner, fixes = _log_pieces(2000, 37)
    phis, inputs = interval_sources(imu_time, steps, cuts, _SETTINGS, 0.005, scheme)
    assert all(np.any(inputs[:, :, r] != 0.0) for r in range(len(SOURCES)))  # every source is exercised
    expected = [compose_intervals(phis, np.ascontiguousarray(inputs[:, :, r : r + 1]), owner, fixes) for r in range(len(SOURCES))]
    phi_k, q_k = composed_sources(imu_time, steps, cuts, owner, fixes, _SETTINGS, 0.005, scheme, chunk=chunk)
    assert q_k.shape == (len(SOURCES), fixes, 3, 3)
    np.testing.assert_array_equal(phi_k, expected[0][0])
    for r in range(len(SOURCES)):
        np.testing.assert_array_equal(q_k[r], expected[r][1])
        np.testing.assert_array_equal(q_k[r], np.swapaxes(q_k[r], 1, 2))


def _peak_bytes(samples: int, chunk: int) -> int:
    imu_time, steps, cuts, owner, fixes = _log_pieces(samples, 40)
    composed_sources(imu_time, steps, cuts, owner, fixes, _SETTINGS, 0.005, "trapezoid", chunk=chunk)  # compiled
    tracemalloc.start()
    try:
        composed_sources(imu_time, steps, cuts, owner, fixes, _SETTINGS, 0.005, "trapezoid", chunk=chunk)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_composed_sources_memory_does_not_grow_with_the_log():
    """The composition's peak memory (numpy's allocations, traced) is that of a chunk, whatever the log's
    length: 8 times the samples at the same chunk size stays within 1.25x; one chunk of all pieces (what
    the test would meet without chunking) grows with the log, by more than 4x."""
    small, large = _peak_bytes(4096, 1024), _peak_bytes(8 * 4096, 1024)
    assert large < 1.25 * small
    assert _peak_bytes(8 * 4096, 10**9) > 4 * _peak_bytes(4096, 10**9)
