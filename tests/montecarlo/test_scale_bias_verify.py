"""The scale/bias verification problem: compiled sums against numpy, the predicted errors-in-variables
mean error against its closed form, and the verdicts of ``verify`` with fixed seeds.

Verdicts: at the default 99% family-wise confidence a correct filter fails a given check with
probability at most 1%; the seeds are fixed, so these are deterministic. The failures asserted here are
tens of standard errors beyond their bounds, not borderline.
"""

from __future__ import annotations

import json
from dataclasses import fields

import numpy as np
import pytest

from kalcal.errors import ConfigError
from kalcal.scenarios.scale_bias.filter import filter_scale_bias
from kalcal.api.verification import verify
from kalcal.scenarios import build_scenario
from kalcal.montecarlo.accumulators import MomentSums
from kalcal.scenarios.scale_bias.problem import ScaleBiasProblem, eiv_mean_error, mean_regressor_signal
from kalcal.montecarlo.scenarios import build_problem

SHORT = ["scenario.duration=8"]  # K = 80: quick, and the prior still counts over much of it


@pytest.mark.parametrize("settings", [[], ["scenario.drift=random-walk"], ["scenario.excitation=reference"]])
def test_the_samples_are_the_draws_written_out_bit_for_bit(settings):
    """sample_scale_bias scales and sums the sensors' noise in place: the numbers of the expressions
    written out (the module docstring's draw order), every bit."""
    from kalcal.scenarios.scale_bias.simulation import _factor, sample_scale_bias

    scenario = build_scenario("scale-bias", assignments=SHORT + settings)
    got = sample_scale_bias(scenario, np.random.default_rng(5), 60)
    rng, s, t, n = np.random.default_rng(5), scenario.scenario, scenario.truth, 60
    prior = scenario.truth_prior()
    theta = prior.mean + rng.standard_normal((n, 2)) @ _factor(prior.cov).T
    theta = np.broadcast_to(theta[:, None, :], (n, s.n_samples, 2))
    if s.drift == "random-walk":
        theta = theta + np.cumsum(rng.standard_normal((n, s.n_samples, 2)) * scenario.truth_drift_std, axis=1)
    eta = rng.standard_normal((n, s.n_samples)) * t.reference_noise_std
    nu = rng.standard_normal((n, s.n_samples)) * t.sensor_noise_std
    profile = scenario.profile(s.sample_times())
    if s.excitation == "sensor":
        clean, psi = np.broadcast_to(profile, (n, s.n_samples)), theta[..., 0] * profile + theta[..., 1]
    else:
        psi, clean = np.broadcast_to(profile, (n, s.n_samples)), (profile - theta[..., 1]) / theta[..., 0]
    for name, want in (("theta", theta), ("psi", psi), ("clean_sensor", clean), ("reference", psi + eta), ("sensor", clean - nu)):
        np.testing.assert_array_equal(getattr(got, name), want, err_msg=name)
        assert getattr(got, name).tobytes() == np.ascontiguousarray(want).tobytes(), name


@pytest.mark.parametrize("settings", [[], ["scenario.drift=random-walk"]])
def test_the_kernel_reads_the_broadcast_truth_as_it_would_a_copy(settings):
    """block_sums hands the kernel the constant truth as a view broadcast along K (no copy): the sums of a
    contiguous copy, bit for bit."""
    from kalcal.scenarios.scale_bias.filter import regressors
    from kalcal.montecarlo.accumulators import SumBuffers
    from kalcal.scenarios.scale_bias.kernels import regression_block_moments
    from kalcal.scenarios.scale_bias.simulation import sample_scale_bias

    scenario = build_scenario("scale-bias", assignments=SHORT + settings)
    samples = sample_scale_bias(scenario, np.random.default_rng(9), 300)
    prior = scenario.filter_prior()
    sums = []
    for truth in (samples.theta, np.ascontiguousarray(samples.theta)):
        buffers = SumBuffers.zeros(samples.time.size, 2, 1, 300, True)
        regression_block_moments(np.ascontiguousarray(samples.reference), np.ascontiguousarray(regressors(samples.sensor)),
                                 truth, prior.mean, prior.cov, float(scenario.filter_noise_variance()),
                                 scenario.filter_process_noise(), True, buffers)  # fmt: skip
        sums.append(MomentSums.from_buffers(300, buffers))
    if not settings:
        assert samples.theta.strides[1] == 0  # the view the engine passes
    for f in fields(MomentSums):
        a, b = getattr(sums[0], f.name), getattr(sums[1], f.name)
        assert (a is None and b is None) or np.array_equal(a, b), f.name


def _checks(outcome) -> dict:
    return {c.name: c for c in outcome.checks}


@pytest.mark.parametrize(
    "settings",
    [[], ["filter.form=note"], ["scenario.drift=random-walk", "filter.parameter_drift_std=2e-3", "truth.sensor_noise_std=0.05"]],
)
def test_compiled_block_sums_equal_the_numpy_path(settings):
    problem = ScaleBiasProblem(build_scenario("scale-bias", assignments=SHORT + settings))
    fast = problem.block_sums(np.random.default_rng(11), 300, "exact")
    slow = MomentSums.from_block(problem.run_block(np.random.default_rng(11), 300, "exact"))
    assert fast.count == slow.count == 300
    for f in fields(MomentSums):
        if f.name == "count":
            continue
        if getattr(slow, f.name) is None:  # optional sums neither path keeps for this problem
            assert getattr(fast, f.name) is None, f.name
            continue
        a, b = np.asarray(getattr(fast, f.name)), np.asarray(getattr(slow, f.name))
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-11 * max(np.abs(b).max(), 1e-300), err_msg=f.name)
    without = ScaleBiasProblem(problem.scenario, residual_pairs=False).block_sums(np.random.default_rng(11), 300, "exact")
    assert without.residual_outer is None
    np.testing.assert_array_equal(without.error_outer, fast.error_outer)


def test_problem_labels():
    problem, cause = build_problem(build_scenario("scale-bias", assignments=["scenario.unit=K"]))
    assert isinstance(problem, ScaleBiasProblem)
    assert problem.info.state_names == ("theta1", "theta2")
    assert problem.info.state_units == ("1", "K")
    assert problem.info.measurement_names == ("reference",) and problem.info.measurement_units == ("K",)
    assert problem.info.update_times.shape == (300,)
    assert problem.engines == ("exact",)
    assert problem.normals_per_realization("exact") == 602
    assert cause.startswith("errors in variables")


def test_eiv_prediction_equals_the_batch_least_squares_expansion():
    """For Q = 0: E[e_k] = (c / R) P_k [(k - 3 + tr(P0^-1 P_k)) e1 + P0^-1 P_k e1], c = theta1 sigma_nu^2."""
    scenario = build_scenario("scale-bias", assignments=["truth.sensor_noise_std=0.1"])
    predicted = eiv_mean_error(scenario)
    prior = scenario.filter_prior()
    r = scenario.filter_noise_variance()
    c = scenario.truth_prior().mean[0] * 0.1**2
    zeta = mean_regressor_signal(scenario)
    h = np.column_stack([zeta, np.ones_like(zeta)])
    p0_inv = np.linalg.solve(prior.cov, np.eye(2))
    e1 = np.array([1.0, 0.0])
    for k in (1, 2, 10, 150, 300):
        cov = np.linalg.solve(p0_inv + h[:k].T @ h[:k] / r, np.eye(2))
        expected = c / r * cov @ ((k - 3 + np.trace(p0_inv @ cov)) * e1 + p0_inv @ cov @ e1)
        np.testing.assert_allclose(predicted[k - 1], expected, rtol=1e-9)


def test_prior_mean_offset_is_the_filters_response_to_the_mean_data():
    """sigma_nu = 0: the filter is linear in v given h, so E[xhat] is its run on E[v] = theta1 zeta + theta2."""
    scenario = build_scenario(
        "scale-bias", assignments=["truth.sensor_noise_std=0", "filter.scale_error=0.03", "filter.bias=-0.1"]
    )
    theta = scenario.truth_prior().mean
    zeta = mean_regressor_signal(scenario)
    run = filter_scale_bias(scenario, theta[0] * zeta + theta[1], zeta)
    np.testing.assert_allclose(eiv_mean_error(scenario), theta - run.posterior, rtol=1e-9, atol=1e-15)
    assert "prior mean" in build_problem(scenario)[1]


def test_verify_passes_with_the_defaults(tmp_path):
    outcome = verify(build_scenario("scale-bias"), 4096, 0, tmp_path)
    assert outcome.summary["verdict"] == "pass", [c.detail for c in outcome.checks if not c.passed]
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["scenario"] == "scale-bias" and summary["final"]["states"] == ["theta1", "theta2"]
    assert summary["model_error"]["max_expected_mean_error_sigma"] < 1e-3
    assert (tmp_path / "stats.nc").is_file()


def test_verify_passes_in_the_notes_form(tmp_path):
    outcome = verify(build_scenario("scale-bias", assignments=SHORT + ["filter.form=note"]), 4096, 1, tmp_path)
    assert outcome.summary["verdict"] == "pass", [c.detail for c in outcome.checks if not c.passed]


def test_verify_shows_the_errors_in_variables_bias(tmp_path):
    scenario = build_scenario("scale-bias", assignments=["truth.sensor_noise_std=0.1"])
    checks = _checks(verify(scenario, 4096, 2, tmp_path))
    mean = checks["mean_error"]
    assert not mean.passed and mean.statistic > 5 * mean.upper
    assert "errors in variables" in mean.detail and "attenuates theta1" in mean.detail
    # The first-order prediction explains the whole deviation.
    assert "after removing it" in mean.detail and "within" in mean.detail
    assert checks["covariance"].passed and checks["nis"].passed


def test_drift_needs_the_matching_q(tmp_path):
    drifting = ["scenario.drift=random-walk"]
    unmatched = _checks(verify(build_scenario("scale-bias", assignments=drifting), 4096, 3, tmp_path / "q0"))
    assert not unmatched["covariance"].passed and unmatched["covariance"].statistic > 5 * unmatched["covariance"].upper
    assert "overconfident" in unmatched["covariance"].detail
    matched = verify(
        build_scenario("scale-bias", assignments=drifting + ["filter.parameter_drift_std=same"]), 4096, 3, tmp_path / "q"
    )
    assert matched.summary["verdict"] == "pass", [c.detail for c in matched.checks if not c.passed]


def test_sampled_engine_is_refused(tmp_path):
    with pytest.raises(ConfigError, match="--engine: 'sampled' is not available for scale-bias"):
        verify(build_scenario("scale-bias", assignments=SHORT), 100, 0, tmp_path, engine="sampled")


@pytest.mark.parametrize("index", [0, 1037, 2499])
def test_a_realization_carries_its_own_filter_covariance(index):
    """The scale/bias filter's P depends on the data: realization K's P is its own filter run's, not the
    mean over its block (which the report's +-1 sigma bands once showed)."""
    from kalcal.montecarlo.engine import block_generator, block_sizes, realization
    from kalcal.scenarios.scale_bias.simulation import sample_scale_bias

    scenario = build_scenario("scale-bias", assignments=SHORT)
    problem = ScaleBiasProblem(scenario)
    n, size = 2500, 1000
    one = realization(problem, seed=4, index=index, n=n, engine="exact", block_size=size)
    block, offset = divmod(index, size)
    data = sample_scale_bias(scenario, block_generator(4, block), block_sizes(n, size)[block])
    own = filter_scale_bias(scenario, data.reference[offset], data.sensor[offset])
    np.testing.assert_allclose(one.filter_cov_sum, own.cov, rtol=1e-12, atol=0)
    np.testing.assert_allclose(one.filter_cov[0], own.cov, rtol=1e-12, atol=0)
    np.testing.assert_allclose(one.estimate[0], own.posterior, rtol=1e-12, atol=1e-15)
    # and it is not the block's mean (the realizations' P differ measurably)
    whole = problem.run_block(block_generator(4, block), block_sizes(n, size)[block], "exact")
    assert not np.allclose(one.filter_cov_sum, whole.filter_cov_sum / whole.error.shape[0], rtol=1e-6)
