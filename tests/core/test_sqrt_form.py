"""The square-root (Cholesky) form against the Joseph and standard forms, FilterPy and exact arithmetic.

Oracles: FilterPy's ``SquareRootKalmanFilter`` (an independent implementation of the same array
algorithm), the Joseph and standard forms on well-conditioned problems, and the Kalman recursion in exact
rational arithmetic (``fractions.Fraction``) on an ill-conditioned one, where the standard form loses
positive definiteness and the square-root form does not.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
from filterpy.kalman import SquareRootKalmanFilter

from kalcal.errors import ConfigError
from kalcal.filters.gains import run_with_gains
from kalcal.core.sqrt_form import (
    cholesky_factor,
    gram,
    interval_noise_factor,
    sqrt_gain_and_factor,
    sqrt_predict,
    sqrt_update,
    triangularize,
)
from kalcal.core.model import LinearGaussianModel
from kalcal.core.steps import covariance_pass, gain_and_covariance, interval_transition, predict, update
from kalcal.scenarios import build_scenario
from kalcal.montecarlo.scenarios import build_problem
from tests._helpers import assert_close, cov_atol


def _spd(rng, d, shift=0.5):
    a = rng.standard_normal((d, d))
    return a @ a.T + shift * np.eye(d)


def _random_model(rng, d=3, p=2, q=3, steps=3) -> LinearGaussianModel:
    """Well conditioned, with a full-rank process noise (FilterPy's square-root filter factors Q)."""
    a = rng.standard_normal((d, d))
    return LinearGaussianModel(
        phi=0.9 * a / np.max(np.abs(np.linalg.eigvals(a))),
        gamma=rng.standard_normal((d, q)),
        h=rng.standard_normal((p, d)),
        w=_spd(rng, q),
        v=_spd(rng, p),
        x0=rng.standard_normal(d),
        m0=_spd(rng, d, 1.0),
        steps_per_update=steps,
        sample_period=0.1,
    )


def _is_lower(a):
    return np.all(np.triu(a, 1) == 0.0)


# --------------------------------------------------------------------------------------------------
# building blocks


def test_triangularize_gives_a_lower_factor_with_the_same_gram_matrix():
    rng = np.random.default_rng(1)
    for cols in (2, 3, 7):
        a = rng.standard_normal((5, 3, cols))
        t = triangularize(a)
        assert t.shape == (5, 3, 3)
        for i in range(5):
            assert _is_lower(t[i]) and np.all(np.diag(t[i]) >= 0)
            np.testing.assert_allclose(t[i] @ t[i].T, a[i] @ a[i].T, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(triangularize(a[i]), t[i], rtol=1e-12, atol=1e-14)
    full = rng.standard_normal((3, 6))
    np.testing.assert_allclose(triangularize(full), np.linalg.cholesky(full @ full.T), rtol=1e-12)


def test_cholesky_factor_handles_singular_covariances():
    rng = np.random.default_rng(2)
    spd = _spd(rng, 3)
    np.testing.assert_array_equal(cholesky_factor(spd), np.linalg.cholesky(spd))
    singular = np.zeros((3, 3))
    singular[:2, :2] = _spd(rng, 2)  # a state no noise reaches, as the bias in accel-gps
    factor = cholesky_factor(singular)
    assert _is_lower(factor)
    np.testing.assert_allclose(factor @ factor.T, singular, rtol=0, atol=1e-14 * np.abs(singular).max())
    batch = cholesky_factor(np.stack([singular, spd]))
    np.testing.assert_allclose(gram(batch), np.stack([singular, spd]), atol=1e-12)


def test_interval_noise_factor_reproduces_q_m():
    model = build_scenario("accel-gps").filter_model()
    _, q_m = interval_transition(model.phi, model.gamma, model.w, model.steps_per_update)
    g = interval_noise_factor(model.phi, model.gamma, model.w, model.steps_per_update)
    assert _is_lower(g)
    assert_close(g @ g.T, q_m, atol=cov_atol(q_m, 1e-12) + 1e-30, what="G G^T")


@pytest.mark.parametrize("per_realization_h", [False, True])
def test_sqrt_steps_equal_joseph_steps_and_batch_equals_loop(per_realization_h):
    rng = np.random.default_rng(3)
    n, d, p = 5, 3, 2
    x = rng.standard_normal((n, d))
    cov = np.stack([_spd(rng, d) for _ in range(n)])
    phi, q = rng.standard_normal((d, d)), _spd(rng, d)
    h = rng.standard_normal((n, p, d)) if per_realization_h else rng.standard_normal((p, d))
    v = _spd(rng, p)
    z = rng.standard_normal((n, p))

    xbar, chol_m = sqrt_predict(x, np.linalg.cholesky(cov), phi, np.linalg.cholesky(q))
    result = sqrt_update(xbar, chol_m, z, h, np.linalg.cholesky(v))
    ref_x, ref_m = predict(x, cov, phi, q)
    ref = update(ref_x, ref_m, z, h, v, "joseph")
    np.testing.assert_allclose(xbar, ref_x, rtol=1e-13)
    assert_close(gram(chol_m), ref_m, atol=cov_atol(ref_m, 1e-12), what="M")
    assert_close(gram(result.chol), ref.cov, atol=cov_atol(ref.cov, 1e-11), what="P")
    assert_close(gram(result.innovation_chol), ref.innovation_cov, atol=cov_atol(ref.innovation_cov, 1e-12), what="S")
    np.testing.assert_allclose(result.gain, ref.gain, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(result.x, ref.x, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(result.residual, ref.residual, rtol=1e-13)
    for i in range(n):
        assert _is_lower(result.chol[i]) and _is_lower(result.innovation_chol[i])
        hi = h[i] if per_realization_h else h
        single = sqrt_update(xbar[i], chol_m[i], z[i], hi, np.linalg.cholesky(v))
        for got, want in zip(result, single):
            np.testing.assert_allclose(got[i], want, rtol=1e-12, atol=1e-14)


def test_sqrt_update_with_zero_h_changes_nothing():
    chol = np.linalg.cholesky(np.array([[2.0, 0.3], [0.3, 1.0]]))
    gain, posterior, s_chol = sqrt_gain_and_factor(chol, np.zeros((1, 2)), np.array([[1.5]]))
    np.testing.assert_array_equal(gain, 0.0)
    np.testing.assert_allclose(posterior, chol, rtol=1e-15, atol=1e-15)
    np.testing.assert_allclose(s_chol, [[1.5]], rtol=1e-15)


def test_sqrt_form_is_refused_where_a_covariance_is_passed():
    with pytest.raises(ConfigError, match="sqrt_update"):
        gain_and_covariance(np.eye(2), np.eye(2), np.eye(2), form="sqrt")
    with pytest.raises(ConfigError, match="form: expected one of joseph, standard, sqrt"):
        covariance_pass(build_scenario("accel-gps").filter_model(), 2, form="cholesky")  # type: ignore[arg-type]


# --------------------------------------------------------------------------------------------------
# well conditioned: the three forms agree to 1e-9


@pytest.mark.parametrize("which", ["accel-gps", "random"])
def test_three_forms_agree_on_well_conditioned_problems(which):
    model = build_scenario("accel-gps").filter_model() if which == "accel-gps" else _random_model(np.random.default_rng(4))
    n_updates = 150
    schedules = {form: covariance_pass(model, n_updates, form) for form in ("joseph", "standard", "sqrt")}
    joseph = schedules["joseph"]
    gain_scale = np.max(np.abs(joseph.gain), axis=(0, 1), keepdims=True)
    z = np.random.default_rng(5).standard_normal((3, n_updates, model.measurement_dim))
    ref_run = run_with_gains(joseph, model.h, z, model.x0)
    sigma = np.sqrt(np.diagonal(joseph.posterior_cov, axis1=1, axis2=2))
    for form in ("standard", "sqrt"):
        s = schedules[form]
        assert_close(s.prior_cov, joseph.prior_cov, atol=cov_atol(joseph.prior_cov, 1e-9), what=f"{form} M")
        assert_close(s.posterior_cov, joseph.posterior_cov, atol=cov_atol(joseph.posterior_cov, 1e-9), what=f"{form} P")
        assert_close(s.gain, joseph.gain, atol=1e-9 * gain_scale, what=f"{form} K")
        np.testing.assert_allclose(s.innovation_cov, joseph.innovation_cov, rtol=1e-9)
        run = run_with_gains(s, model.h, z, model.x0)
        assert_close(run.posterior, ref_run.posterior, atol=1e-9 * sigma, what=f"{form} states")


def test_fixed_gain_problem_takes_the_sqrt_form():
    scenario = build_scenario("accel-gps", assignments=["scenario.duration=4"])
    joseph, _ = build_problem(scenario, "joseph")
    sqrt, _ = build_problem(scenario, "sqrt")
    assert sqrt.form == "sqrt"
    cov = joseph.schedule.posterior_cov
    assert_close(sqrt.schedule.posterior_cov, cov, atol=cov_atol(cov, 1e-9), what="P")
    a = joseph.run_block(np.random.default_rng(6), 50, "exact")
    b = sqrt.run_block(np.random.default_rng(6), 50, "exact")
    sigma = np.sqrt(np.diagonal(cov, axis1=1, axis2=2))
    assert_close(b.estimate, a.estimate, atol=1e-9 * sigma, what="estimates")
    np.testing.assert_allclose(b.nees, a.nees, rtol=1e-8)


def test_sqrt_filter_matches_filterpy_square_root_filter():
    rng = np.random.default_rng(7)
    model = _random_model(rng, steps=1)
    q = model.gamma @ model.w @ model.gamma.T
    kf = SquareRootKalmanFilter(dim_x=3, dim_z=2)
    kf.F, kf.H, kf.Q, kf.R = model.phi.copy(), model.h.copy(), q.copy(), model.v.copy()
    kf.x = model.x0.reshape(3, 1).copy()
    kf.P = model.m0.copy()
    x, chol = model.x0, np.linalg.cholesky(model.m0)
    q_chol, v_chol = np.linalg.cholesky(q), np.linalg.cholesky(model.v)
    for z in rng.standard_normal((40, 2)) * 3.0:
        kf.predict()
        kf.update(z.reshape(2, 1))
        x, chol = sqrt_predict(x, chol, model.phi, q_chol)
        result = sqrt_update(x, chol, z, model.h, v_chol)
        x, chol = result.x, result.chol
        # FilterPy's factor may differ in the signs of its columns; the covariances may not.
        assert_close(gram(chol), kf.P, atol=cov_atol(kf.P, 1e-10), what="P vs FilterPy")
        np.testing.assert_allclose(x, kf.x[:, 0], rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(result.gain, kf.K, rtol=1e-9, atol=1e-12)


# --------------------------------------------------------------------------------------------------
# ill conditioned: huge prior variance, a very precise measurement of one component


ILL_PHI = np.array([[1.0, 0.5], [0.0, 1.0]])
ILL_M0 = 1e12 * np.array([[1.0, 0.5], [0.5, 1.0]])
ILL_H = np.array([[1.0, 0.0]])
ILL_V = np.array([[1e-12]])
ILL_Q = 1e-20 * np.eye(2)  # FilterPy's square-root filter needs a positive definite Q
ILL_UPDATES = 8


def _exact_posteriors() -> np.ndarray:
    """The Kalman recursion in exact rational arithmetic on the same (binary) inputs, rounded at the end."""

    def frac(a):
        return [[Fraction(float(x)) for x in row] for row in np.atleast_2d(a)]

    def mul(a, b):
        return [[sum(a[i][k] * b[k][j] for k in range(len(b))) for j in range(len(b[0]))] for i in range(len(a))]

    def tr(a):
        return [list(r) for r in zip(*a)]

    phi, h, v, q, cov = frac(ILL_PHI), frac(ILL_H), frac(ILL_V), frac(ILL_Q), frac(ILL_M0)
    out = []
    for _ in range(ILL_UPDATES):
        cov = [[a + b for a, b in zip(r, s)] for r, s in zip(mul(mul(phi, cov), tr(phi)), q)]
        s = mul(mul(h, cov), tr(h))[0][0] + v[0][0]
        gain = [[row[0] / s] for row in mul(cov, tr(h))]
        cov = [[a - b for a, b in zip(r, t)] for r, t in zip(cov, mul(gain, mul(h, cov)))]
        out.append([[float(x) for x in row] for row in cov])
    return np.array(out)


def _is_positive_definite(cov) -> bool:
    try:
        np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        return False
    return bool(np.linalg.eigvalsh(cov).min() > 0)


def test_standard_form_loses_definiteness_where_the_sqrt_form_does_not():
    exact = _exact_posteriors()
    assert all(_is_positive_definite(p) for p in exact)  # the true posteriors are positive definite

    standard, cov = [], ILL_M0
    for _ in range(ILL_UPDATES):
        _, cov = predict(np.zeros(2), cov, ILL_PHI, ILL_Q)
        _, cov, _ = gain_and_covariance(cov, ILL_H, ILL_V, "standard")
        standard.append(cov)
    broken = [k for k, p in enumerate(standard) if not _is_positive_definite(p)]
    assert broken, "the standard form stayed positive definite"
    smallest = min(np.linalg.eigvalsh(standard[k]).min() for k in broken)
    assert smallest <= 0.0  # a zero or negative eigenvalue, or a failed Cholesky

    sqrt, chol = [], cholesky_factor(ILL_M0)
    q_chol, v_chol = cholesky_factor(ILL_Q), cholesky_factor(ILL_V)
    for _ in range(ILL_UPDATES):
        _, chol = sqrt_predict(np.zeros(2), chol, ILL_PHI, q_chol)
        _, chol, _ = sqrt_gain_and_factor(chol, ILL_H, v_chol)
        assert _is_lower(chol) and np.all(np.diag(chol) > 0)
        sqrt.append(gram(chol))
    assert all(_is_positive_definite(p) for p in sqrt)
    # Accurate to the conditioning of the factor, about eps * 1e12 ~ 1e-4 relative: the standard form is off
    # by whole standard deviations (its position variance is ~1e-20 where the truth is ~1e-12).
    assert_close(np.array(sqrt), exact, atol=cov_atol(exact, 1e-3), what="sqrt vs exact")
    with pytest.raises(AssertionError):
        assert_close(np.array(standard), exact, atol=cov_atol(exact, 0.5), what="standard vs exact")


def test_sqrt_form_matches_filterpy_on_the_ill_conditioned_problem():
    kf = SquareRootKalmanFilter(dim_x=2, dim_z=1)
    kf.F, kf.H, kf.Q, kf.R = ILL_PHI.copy(), ILL_H.copy(), ILL_Q.copy(), ILL_V.copy()
    kf.P = ILL_M0.copy()
    chol = cholesky_factor(ILL_M0)
    q_chol, v_chol = cholesky_factor(ILL_Q), cholesky_factor(ILL_V)
    for _ in range(ILL_UPDATES):
        kf.predict()
        kf.update(np.zeros((1, 1)))
        _, chol = sqrt_predict(np.zeros(2), chol, ILL_PHI, q_chol)
        _, chol, _ = sqrt_gain_and_factor(chol, ILL_H, v_chol)
        assert _is_positive_definite(kf.P)
        assert_close(gram(chol), kf.P, atol=cov_atol(kf.P, 1e-9), what="P vs FilterPy")
