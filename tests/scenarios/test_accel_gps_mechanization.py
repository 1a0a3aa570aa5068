"""Strapdown integration against the report's recursion written as a plain loop, and closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from kalcal.errors import ConfigError
from kalcal.scenarios.accel_gps.mechanization import integrate, interval_weights
from tests._helpers import assert_close


def _loop(accel, dt, p0, v0, scheme):
    """The recursions of the module docstring (the report's equations for Euler), sample by sample."""
    n = len(accel)
    dt = np.broadcast_to(np.asarray(dt, dtype=float), (n - 1,))
    p, v = np.empty(n), np.empty(n)
    p[0], v[0] = p0, v0
    for j in range(n - 1):
        if scheme == "euler":
            v[j + 1] = v[j] + accel[j] * dt[j]
            p[j + 1] = p[j] + v[j] * dt[j] + accel[j] * dt[j] ** 2 / 2
        else:
            v[j + 1] = v[j] + (accel[j] + accel[j + 1]) * dt[j] / 2
            p[j + 1] = p[j] + v[j] * dt[j] + (2 * accel[j] + accel[j + 1]) * dt[j] ** 2 / 6
    return p, v


def _assert_matches_loop(got, want):
    # rtol 1e-13 on the values, with an absolute floor at 1e-13 of the largest value for entries that
    # pass near zero (the cumulative sum rounds in a different order than the loop).
    for g, w in zip(got, want):
        assert_close(g, w, rtol=1e-13, atol=1e-13 * np.max(np.abs(w)))


@pytest.mark.parametrize("scheme", ["euler", "trapezoid"])
def test_integrate_matches_loop(scheme):
    rng = np.random.default_rng(1)
    accel = 10 * np.sin(0.1 * np.arange(801) * 0.005) + 0.1 + 0.02 * rng.standard_normal(801)
    got = integrate(accel, 0.005, 3.0, 100.0, scheme)
    _assert_matches_loop(got, _loop(accel, 0.005, 3.0, 100.0, scheme))


@pytest.mark.parametrize("scheme", ["euler", "trapezoid"])
def test_integrate_uneven_steps_match_loop(scheme):
    rng = np.random.default_rng(2)
    accel = rng.standard_normal(301)
    dt = 0.01 * (1 + 0.5 * rng.random(300))
    got = integrate(accel, dt, -2.0, 5.0, scheme)
    _assert_matches_loop(got, _loop(accel, dt, -2.0, 5.0, scheme))


@pytest.mark.parametrize("scheme", ["euler", "trapezoid"])
def test_integrate_batch_equals_loop_over_rows(scheme):
    rng = np.random.default_rng(3)
    accel = rng.standard_normal((4, 101))
    p0, v0 = rng.standard_normal(4), 10 + rng.standard_normal(4)
    position, velocity = integrate(accel, 0.02, p0, v0, scheme)
    assert position.shape == velocity.shape == (4, 101)
    for i in range(4):
        p_i, v_i = integrate(accel[i], 0.02, p0[i], v0[i], scheme)
        np.testing.assert_array_equal(position[i], p_i)
        np.testing.assert_array_equal(velocity[i], v_i)
        _assert_matches_loop((p_i, v_i), _loop(accel[i], 0.02, p0[i], v0[i], scheme))


def test_euler_ignores_last_sample_trapezoid_uses_it():
    accel = np.array([1.0, 2.0, 3.0])
    changed = accel.copy()
    changed[-1] = 100.0
    e1, e2 = integrate(accel, 0.1, 0, 0, "euler"), integrate(changed, 0.1, 0, 0, "euler")
    np.testing.assert_array_equal(e1[0], e2[0])
    np.testing.assert_array_equal(e1[1], e2[1])
    t1, t2 = integrate(accel, 0.1, 0, 0, "trapezoid"), integrate(changed, 0.1, 0, 0, "trapezoid")
    assert t1[1][-1] != t2[1][-1]


@pytest.mark.parametrize("scheme", ["euler", "trapezoid"])
def test_constant_acceleration_is_exact(scheme):
    dt, n, a, p0, v0 = 0.005, 2001, 0.37, 12.0, -3.5
    t = np.arange(n) * dt
    position, velocity = integrate(np.full(n, a), dt, p0, v0, scheme)
    np.testing.assert_allclose(velocity, v0 + a * t, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(position, p0 + v0 * t + a * t**2 / 2, rtol=1e-12, atol=1e-12)


def test_trapezoid_velocity_is_exact_for_linear_acceleration():
    dt, n = 0.01, 501
    t = np.arange(n) * dt
    _, velocity = integrate(2.0 + 0.3 * t, dt, 0.0, 1.0, "trapezoid")
    np.testing.assert_allclose(velocity, 1.0 + 2.0 * t + 0.15 * t**2, rtol=1e-12)


@pytest.mark.parametrize("scheme", ["euler", "trapezoid"])
@pytest.mark.parametrize("steps", [1, 2, 40])
def test_interval_weights_sum_to_constant_acceleration_motion(scheme, steps):
    dt = 0.005
    weights = interval_weights(scheme, dt, steps)
    assert weights.shape == (steps + 1, 2)
    big_t = steps * dt
    np.testing.assert_allclose(weights.sum(axis=0), [big_t**2 / 2, big_t], rtol=1e-12)


def test_euler_weights_closed_form():
    dt, m = 0.005, 40
    weights = interval_weights("euler", dt, m)
    np.testing.assert_array_equal(weights[m], [0.0, 0.0])
    i = np.arange(m)
    np.testing.assert_allclose(weights[:m, 0], dt**2 / 2 + (m - 1 - i) * dt**2, rtol=1e-12)
    np.testing.assert_allclose(weights[:m, 1], dt, rtol=1e-12)


def test_trapezoid_weights_closed_form():
    dt, m = 0.005, 40
    weights = interval_weights("trapezoid", dt, m)
    i = np.arange(m + 1)
    # Sample i closes step i - 1 (if i >= 1) and opens step i (if i < m); each use adds dt/2 to the
    # velocity and dt/2 * dt to the position per later step; in its own step it adds dt^2/3 to the
    # position as the opening sample and dt^2/6 as the closing one (the line between them, integrated).
    closes = (i >= 1) * (dt**2 / 6 + (m - i) * dt**2 / 2)
    opens = (i < m) * (dt**2 / 3 + (m - 1 - i) * dt**2 / 2)
    np.testing.assert_allclose(weights[:, 0], closes + opens, rtol=1e-12)
    np.testing.assert_allclose(weights[:, 1], np.where((i == 0) | (i == m), dt / 2, dt), rtol=1e-12)
    assert weights[m, 0] > 0 and weights[m, 1] > 0


@pytest.mark.parametrize("scheme", ["euler", "trapezoid"])
def test_interval_weights_are_the_integration_map(scheme):
    """[p, v] after one interval from rest equals accel @ weights for any samples."""
    rng = np.random.default_rng(4)
    accel = rng.standard_normal(41)
    position, velocity = _loop(accel, 0.005, 0.0, 0.0, scheme)
    np.testing.assert_allclose(accel @ interval_weights(scheme, 0.005, 40), [position[-1], velocity[-1]], rtol=1e-12)


def test_unknown_scheme_is_config_error():
    with pytest.raises(ConfigError, match="integration"):
        integrate(np.zeros(3), 0.1, 0.0, 0.0, "rk4")  # type: ignore[arg-type]


@pytest.mark.parametrize("scheme", ["euler", "trapezoid"])
def test_partial_step_cut_anywhere_matches_the_whole_step(scheme):
    """A step cut at tau and continued by the line's remainder ends where the whole step ends."""
    from kalcal.scenarios.accel_gps.mechanization import partial_step

    a0, a1, dt, p0, v0 = 0.7, -1.3, 0.005, 12.0, 3.0
    p_whole, v_whole = integrate(np.array([a0, a1]), dt, p0, v0, scheme)
    p_end, v_end = partial_step(a0, a1, dt, dt, p0, v0, scheme)
    assert p_end == pytest.approx(p_whole[-1], rel=1e-14) and v_end == pytest.approx(v_whole[-1], rel=1e-14)
    if scheme == "trapezoid":
        # exact for an acceleration that is a straight line in time: a(t) = a0 + (a1 - a0) t / dt
        tau = 0.3 * dt
        p_cut, v_cut = partial_step(a0, a1, dt, tau, p0, v0, scheme)
        slope = (a1 - a0) / dt
        assert v_cut == pytest.approx(v0 + a0 * tau + slope * tau**2 / 2, rel=1e-14)
        assert p_cut == pytest.approx(p0 + v0 * tau + a0 * tau**2 / 2 + slope * tau**3 / 6, rel=1e-14)


def test_an_unknown_scheme_is_refused_by_the_settings_layer():
    from kalcal.models.settings import SettingError

    with pytest.raises(SettingError, match=r"^scenario.integration: expected one of euler, trapezoid, got 'rk4'$"):
        integrate(np.zeros(5), 0.01, 0.0, 0.0, "rk4")
