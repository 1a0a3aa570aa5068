"""The compiled filter of a time-varying model against its numpy reference, row by row, and the run's
conventions (statsmodels referees the reference itself: tests/core/test_statsmodels_referee.py)."""

from __future__ import annotations

import numpy as np
import pytest

from kalcal.core.likelihood import innovation_loglik
from kalcal.core.timevarying import TimeVaryingModel
from kalcal.core.timevarying_filter import filter_model, loglik, reference_filter, smooth


def _model(n, *, diffuse, seed=7, missing=True):
    """d = 3 (a position, a velocity and a constant bias, the bias diffuse if asked), p = 2, rows that
    change per step (the second row's gain on the bias is a regressor from data), V_j correlated and
    changing per row, a known input on the velocity, and simulated data with missing components."""
    rng = np.random.default_rng(seed)
    dt = 0.1
    phi = np.array([[1.0, dt, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    gamma = np.array([[0.5 * dt * dt], [dt], [0.0]])
    w = np.array([[0.04]])
    b = np.array([[0.5 * dt * dt], [dt], [0.0]])
    u = np.sin(0.01 * np.arange(n))[:, None]
    h = np.zeros((n, 2, 3))
    h[:, 0, 0] = 1.0
    h[:, 1, 1] = 1.0
    h[:, 1, 2] = 1.0 + 0.3 * np.cos(0.003 * np.arange(n))
    sd = np.column_stack([0.5 + 0.2 * rng.random(n), 0.1 + 0.05 * rng.random(n)])
    v = np.einsum("ji,jk->jik", sd, sd) * np.array([[1.0, 0.3], [0.3, 1.0]])
    x = np.array([0.0, 1.0, 0.2])
    z = np.empty((n, 2))
    for j in range(n):
        z[j] = h[j] @ x + np.linalg.cholesky(v[j]) @ rng.standard_normal(2)
        x = phi @ x + b @ u[j] + gamma @ (np.sqrt(w[0, 0]) * rng.standard_normal(1))
    if missing:
        z[rng.random(n) < 0.2, 0] = np.nan
        z[rng.random(n) < 0.1, 1] = np.nan
    flags = np.array([False, False, diffuse])
    m0 = np.diag([1.0, 0.25, 0.0 if diffuse else 1.0])
    model = TimeVaryingModel(phi=phi, gamma=gamma, w=w, b=b, x0=[0.0, 1.0, 0.0], m0=m0, h=h, v=v, u=u, diffuse=flags,
                             sample_period=dt, times=dt * np.arange(n))  # fmt: skip
    return model, z


def _same(ours, reference, rtol, what):
    """Equal to ``rtol`` of each series' largest magnitude, NaN exactly where the reference's is."""
    ours, reference = np.asarray(ours, dtype=float), np.asarray(reference, dtype=float)
    assert np.array_equal(np.isnan(ours), np.isnan(reference)), what
    scale = np.nanmax(np.abs(reference), axis=0, keepdims=True)
    assert np.all(np.nan_to_num(np.abs(ours - reference)) <= rtol * np.nan_to_num(scale)), what


@pytest.mark.parametrize("diffuse", [False, True])
def test_compiled_filter_equals_the_numpy_reference_at_every_row(diffuse):
    model, z = _model(3000, diffuse=diffuse)
    ref, run = reference_filter(model, z), filter_model(model, z)
    for field in ("state", "cov", "prior_state", "prior_cov", "residual", "innovation_cov", "nis"):
        _same(getattr(run, field), getattr(ref, field), 1e-12, field)
    assert np.array_equal(run.measured, ref.measured) and np.array_equal(run.conditioned, ref.conditioned)
    assert run.loglik == pytest.approx(ref.loglik, rel=1e-12)
    assert loglik(model, z) == pytest.approx(ref.loglik, rel=1e-12)
    assert run.proper_from == ref.proper_from
    if diffuse:  # the bias is determined at the first row that sees it (row 0's second component, if measured)
        assert run.conditioned.sum() == 1 and run.diffuse_term < 0
        assert np.isnan(run.state[: run.proper_from, 2]).all() and np.isfinite(run.state[run.proper_from :]).all()
    else:
        assert not run.conditioned.any() and run.diffuse_term == 0.0 and run.proper_from == 0


def test_univariate_likelihood_is_the_joint_prediction_error_decomposition():
    """With every component measured and a known prior, the decorrelated one-at-a-time terms (and their
    Jacobian) sum to the joint -1/2 sum (log det S_j + r_j^T S_j^{-1} r_j + p log 2 pi)."""
    model, z = _model(500, diffuse=False, missing=False)
    run = filter_model(model, z)
    assert run.loglik == pytest.approx(innovation_loglik(run.residual, run.innovation_cov), rel=1e-12)


def test_nis_is_chi_square_for_the_true_model():
    """The NIS of the true model's rows is chi-square with the row's measured count m_j as degrees of
    freedom, independent across rows: sum_j (NIS_j - m_j) has mean 0 and variance sum_j 2 m_j, so a right
    NIS stays within 4 standard deviations (fixed seed; a false alarm has probability ~6e-5)."""
    model, z = _model(3000, diffuse=False)
    run = filter_model(model, z)
    used = np.isfinite(run.nis)
    dof = run.measured[used].sum(axis=1)
    stat = np.sum(run.nis[used] - dof)
    assert abs(stat) < 4.0 * np.sqrt(np.sum(2.0 * dof))


def test_smoother_rows_before_the_diffuse_period_ends_are_nan():
    model, z = _model(400, diffuse=True)
    run = filter_model(model, z)
    smoothed = smooth(run, model)
    assert np.isnan(smoothed.state[: run.proper_from]).all()
    assert np.isfinite(smoothed.state[run.proper_from :]).all()
    # the smoother's last row is the filter's
    np.testing.assert_array_equal(smoothed.state[-1], run.state[-1])


def test_wrong_shape_of_data_is_refused():
    model, z = _model(50, diffuse=False)
    with pytest.raises(ValueError, match="z: expected shape"):
        filter_model(model, z[:, :1])


def test_three_correlated_components_likelihood_is_the_joint_decomposition():
    """p = 3 correlated components (the batched Cholesky path of the decorrelation; p = 2 takes a closed
    form, held by the test above): the univariate terms sum to the joint decomposition."""
    rng = np.random.default_rng(3)
    n = 300
    h = rng.standard_normal((n, 3, 2))
    root = rng.standard_normal((n, 3, 3))
    v = root @ np.swapaxes(root, 1, 2) + np.eye(3)
    model = TimeVaryingModel(phi=[[0.9, 0.1], [0.0, 0.95]], gamma=np.eye(2), w=np.diag([0.1, 0.2]), b=np.zeros((2, 0)),
                             x0=[0.0, 0.0], m0=np.eye(2), h=h, v=v, u=np.zeros((n, 0)), diffuse=[False, False],
                             sample_period=1.0, times=np.arange(n, dtype=float))  # fmt: skip
    z = rng.standard_normal((n, 3)) * 2.0
    run = filter_model(model, z)
    assert run.loglik == pytest.approx(innovation_loglik(run.residual, run.innovation_cov), rel=1e-12)
    _same(run.state, reference_filter(model, z).state, 1e-12, "state")


def _fields(n=4, d=2, m=1):
    return dict(phi=np.eye(d), gamma=np.eye(d), w=np.eye(d), b=np.ones((d, m)), x0=np.zeros(d), m0=np.eye(d),
                h=np.ones((n, 1, d)), v=np.ones((n, 1, 1)), u=np.zeros((n, m)), diffuse=np.zeros(d, dtype=bool),
                sample_period=1.0, times=np.arange(n, dtype=float))  # fmt: skip


# b and u take their exact shapes: a (1, 2) b with d = 2 was read as (2, 1), a (2, 2) b with d = 4 as
# (4, 1), a u of (n * m,) as (n, m); a shape that divides nothing raised a bare ValueError of numpy's.
@pytest.mark.parametrize(
    "field, value, d, words",
    [
        ("b", np.ones((1, 2)), 2, r"b: expected a matrix of shape \(2, m\)"),
        ("b", np.ones((2, 2)), 4, r"b: expected a matrix of shape \(4, m\)"),
        ("b", np.ones(2), 2, r"b: expected a matrix \(2 dimensions\)"),
        ("b", np.ones((3, 1)), 2, r"b: expected a matrix of shape \(2, m\)"),
        ("u", np.zeros(4), 2, r"u: expected a matrix \(2 dimensions\)"),
        ("u", np.zeros((1, 4)), 2, r"u: expected inputs of shape \(4, 1\)"),
        ("u", np.zeros((3, 1)), 2, r"u: expected inputs of shape \(4, 1\)"),
        ("b", [[1.0, 2.0], [3.0]], 2, "b: expected a matrix of numbers"),
    ],
)
def test_inputs_of_a_wrong_shape_are_refused_naming_the_field(field, value, d, words):
    from kalcal.models.settings import SettingError

    fields = _fields(d=d)
    fields[field] = value
    with pytest.raises(SettingError, match=words):
        TimeVaryingModel(**fields)


def test_no_inputs_read_as_none_an_empty_list_or_d_by_0():
    for b, u in ((None, None), ([], []), (np.zeros((2, 0)), np.zeros((4, 0)))):
        fields = _fields()
        fields.update(b=b, u=u)
        model = TimeVaryingModel(**fields)
        assert model.b.shape == (2, 0) and model.u.shape == (4, 0)
