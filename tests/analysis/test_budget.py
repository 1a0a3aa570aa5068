"""The error budget: its terms sum to the true error covariance, and a source set to zero has no term."""

from __future__ import annotations

import numpy as np
import pytest

from kalcal.analysis.fixed_gain import analyze_scenario
from kalcal.core.sources import blocks, model_sources
from kalcal.scenarios.model_file.model import parse_model
from kalcal.scenarios import build_scenario
from kalcal.scenarios.accel_gps.truth import accel_gps_process_noise, accel_gps_truth
from tests._helpers import assert_close, cov_atol

SETTINGS = [
    [],
    ["scenario.integration=trapezoid", "truth.bias_walk_std=2e-4"],
    ["truth.bias_correlation_time=20", "truth.accel_noise_std=0.05", "filter.accel_noise_std=0.02"],
    ["truth.scale_std=1e-3", "scenario.integration=trapezoid"],
]


@pytest.mark.parametrize("assignments", SETTINGS)
def test_terms_sum_to_the_true_error_covariance(assignments):
    result = analyze_scenario(build_scenario("accel-gps", assignments=assignments), pairs=False)
    total = sum(term.error_cov for term in result.budget)
    cov = result.moments.error_cov
    assert_close(total, cov, rtol=1e-9, atol=cov_atol(cov, 1e-9), what="sum of the budget")
    for term in result.budget:  # each term is a covariance in its own right
        assert np.all(np.linalg.eigvalsh(term.error_cov) > -1e-12 * np.abs(cov).max())


@pytest.mark.parametrize("assignments", SETTINGS)
def test_accel_gps_process_sources_sum_to_the_sampled_noise(assignments):
    scenario = build_scenario("accel-gps", assignments=assignments)
    truth = accel_gps_truth(scenario)
    process = accel_gps_process_noise(scenario)
    q = sum(share for _, share, _ in process)
    l_lt = truth.noise_factor @ truth.noise_factor.T
    assert_close(q, l_lt, atol=1e-12 * np.abs(l_lt).max(), what="Q")
    assert sum(u for _, _, u in process) == float(truth.shares_boundary)


def test_accel_gps_sources_are_named_by_component():
    result = analyze_scenario(build_scenario("accel-gps", assignments=["truth.bias_walk_std=2e-4"]), pairs=False)
    assert [(t.source, t.kind) for t in result.budget] == [
        ("prior:position", "prior"), ("prior:velocity", "prior"), ("prior:bias", "prior"),
        ("process:accel", "process"), ("process:bias", "process"),
        ("measurement:position", "measurement"), ("measurement:velocity", "measurement"),
    ]  # fmt: skip


def test_removing_a_source_removes_its_term():
    """With the filter's settings held, a truth variance set to zero zeroes its term and leaves the others."""
    held = ["filter.bias_std=0.1"]
    base = analyze_scenario(build_scenario("accel-gps", assignments=held), pairs=False)
    without = analyze_scenario(build_scenario("accel-gps", assignments=[*held, "truth.bias_std=0"]), pairs=False)
    terms = {t.source: t.error_cov for t in base.budget}
    for term in without.budget:
        if term.source == "prior:bias":
            assert np.all(term.error_cov == 0.0)
        else:
            assert_close(term.error_cov, terms[term.source], rtol=1e-12, atol=1e-15, what=term.source)
    assert_close(
        without.moments.error_cov, base.moments.error_cov - terms["prior:bias"], atol=cov_atol(base.moments.error_cov, 1e-9), what="total"
    )
    # a drifting bias's process term disappears with its noise
    walk = analyze_scenario(build_scenario("accel-gps", assignments=["truth.bias_walk_std=2e-4", "filter.bias_walk_std=2e-4"]), pairs=False)
    still = analyze_scenario(build_scenario("accel-gps", assignments=["filter.bias_walk_std=2e-4"]), pairs=False)
    assert "process:bias" in {t.source for t in walk.budget}
    assert "process:bias" not in {t.source for t in still.budget}


def test_model_file_sources_follow_the_blocks_of_m0_w_and_v():
    text = """
steps_per_update = 2
updates = 10
phi = [[1.0, 0.1, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.9]]
gamma = [[0.005, 0.0], [0.1, 0.0], [0.0, 1.0]]
h = [[1.0, 0.0, 1.0], [0.0, 1.0, 0.0]]
w = [[0.04, 0.0], [0.0, 0.01]]
v = [[4.0, 0.1], [0.1, 0.5]]
x0 = [0.0, 1.0, 0.0]
m0 = [[25.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 0.1]]
state_names = ["p", "v", "c"]
measurement_names = ["zp", "zv"]

[truth]
w = [[0.09, 0.0], [0.0, 0.02]]
"""
    scenario = parse_model(text, "three.toml")
    names = [s.name for s in model_sources(scenario.truth, ("p", "v", "c"), ("zp", "zv"))]
    assert names == ["prior:p+v", "prior:c", "process:w1", "process:w2", "measurement:zp+zv"]
    result = analyze_scenario(scenario)
    cov = result.moments.error_cov
    assert_close(sum(t.error_cov for t in result.budget), cov, rtol=1e-9, atol=cov_atol(cov, 1e-9), what="budget")


def test_blocks_are_the_connected_components():
    matrix = np.array([[1.0, 0, 0, 0.2], [0, 2.0, 0, 0], [0, 0, 0.0, 0], [0.2, 0, 0, 3.0]])
    assert [b.tolist() for b in blocks(matrix)] == [[0, 3], [1], [2]]
