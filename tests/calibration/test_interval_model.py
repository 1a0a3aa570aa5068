"""The compiled composition of an interval's pieces against the numpy reference predict of covariances.

Oracle: :func:`kalcal.filters.steps.predict_covariance` applied piece by piece (Q <- T Q T^T + G G^T from
Q = 0, Phi <- T Phi from I), and :func:`kalcal.filters.steps.interval_transition` where every piece is the
same sample step.
"""

from __future__ import annotations

import numpy as np
import pytest

from kalcal.calibration.interval_model import compose_intervals
from kalcal.filters.steps import interval_transition, predict_covariance


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
