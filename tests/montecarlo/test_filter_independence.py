"""The filter of a verification problem depends on no truth setting it does not share.

Every ``filter.*`` value is set explicitly (an unset one means "the truth's", which is sharing by
definition); then each ``truth.*`` setting in turn is perturbed, and the filter's model, covariances,
gains and transitions must stay bit for bit the same. The accel-gps filter shares exactly the
acceleration profile (``accel_amplitude``, ``accel_frequency``) and only through the scale factor's
column, so with a scale state those two must change the transitions and nothing else may.
"""

import dataclasses

import numpy as np
import pytest

from kalcal.errors import ConfigError
from kalcal.scenarios.accel_gps.settings import DENSITY_NAMES, AccelGpsFilter, AccelGpsTruth
from kalcal.scenarios import build_scenario
from kalcal.scenarios.scale_bias.settings import ScaleBiasTruth
from kalcal.montecarlo.scenarios import build_problem

SHORT = ["scenario.duration=4"]
#: what the filter is allowed to share with the truth, and only with a scale-factor state
SHARED_PROFILE = {"accel_amplitude", "accel_frequency"}

ACCEL_CONFIGS = {
    "report": [],
    "scale": ["truth.scale_std=1e-3", "filter.scale_std=1e-3", "filter.bias_correlation_time=0"],
    "scale-trapezoid-markov": [
        "truth.scale_std=1e-3", "filter.scale_std=1e-3", "filter.bias_correlation_time=5", "scenario.integration=trapezoid",
    ],
    "walk": ["filter.bias_walk_std=2e-4"],
    "markov": ["filter.bias_correlation_time=5"],
    "analytic-trapezoid": ["scenario.integration=trapezoid", "filter.bias_walk_std=1e-4"],
}


def _explicit_filter(assignments: list[str]) -> list[str]:
    """Every filter.* key given a value (the truth's default unless the config sets it)."""
    given = {a.split("=", 1)[0] for a in assignments}
    defaults = AccelGpsTruth().at_rate(200.0)  # the truth's defaults, per sample
    extra = [
        f"filter.{f.name}={getattr(defaults, f.name, 0.0)!r}"  # a filter-only setting (gps_latency): 0
        for f in dataclasses.fields(AccelGpsFilter)
        if f"filter.{f.name}" not in given and f.name not in DENSITY_NAMES  # a density or its per-sample value
    ]
    return [*assignments, *extra]


def _perturbed(name: str, value: float | None) -> float | str:
    if name == "gps_noise":  # the law of the fixes' noise: the other one
        return "student-t" if value == "gaussian" else "gaussian"
    if name == "gps_noise_dof":  # a whole number of degrees of freedom
        return value + 2
    if value is None:  # a density the truth was not given: one
        return 3e-3
    return 5.0 if name == "bias_correlation_time" and value == 0 else (2e-4 if value == 0 else 1.7 * value + 0.3)


def _accel_filter(assignments):
    problem, _ = build_problem(build_scenario("accel-gps", None, [*SHORT, *assignments]))
    model = problem.filter_model
    arrays = {f.name: getattr(model, f.name) for f in dataclasses.fields(model)}
    schedule = problem.schedule
    arrays.update(
        posterior_cov=schedule.posterior_cov,
        prior_cov=schedule.prior_cov,
        gain=schedule.gain,
        transitions=schedule.transitions,
        innovation_cov=schedule.innovation_cov,
    )
    return arrays


def _differing(a: dict, b: dict) -> list[str]:
    return [k for k in a if not np.array_equal(np.asarray(a[k]), np.asarray(b[k]))]


@pytest.mark.parametrize("config", list(ACCEL_CONFIGS))
@pytest.mark.parametrize("name", [f.name for f in dataclasses.fields(AccelGpsTruth)])
def test_accel_gps_filter_ignores_every_truth_setting_it_does_not_share(config, name):
    assignments = _explicit_filter(ACCEL_CONFIGS[config])
    truth_value = getattr(build_scenario("accel-gps", None, assignments).given_truth, name)
    if name == "scale_std" and truth_value == 0:
        # a filter without a scale state against a truth with one is refused, by design: nothing to compare
        with pytest.raises(ConfigError, match="filter.scale_std"):
            build_scenario("accel-gps", None, [*assignments, "truth.scale_std=1e-3"])
        return
    base = _accel_filter(assignments)
    value = _perturbed(name, truth_value)
    moved = _accel_filter([*assignments, f"truth.{name}={value if isinstance(value, str) else repr(value)}"])
    changed = _differing(base, moved)
    has_scale = "filter.scale_std=1e-3" in assignments
    if has_scale and name in SHARED_PROFILE:
        # the scale column is the shared profile: it (and what follows from it) must move, the model must not
        assert "transitions" in changed and not {"phi", "gamma", "w", "h", "v", "x0", "m0"} & set(changed)
    else:
        assert changed == [], f"truth.{name} changed the filter's {changed}"


def test_the_issue_case_bias_correlation_time():
    """The measured case: with a scale state, truth.bias_correlation_time 0 -> 5 moved the filter's P."""
    assignments = ["truth.scale_std=1e-3", "filter.scale_std=1e-3", "filter.bias_correlation_time=0"]
    base = _accel_filter(assignments)
    moved = _accel_filter([*assignments, "truth.bias_correlation_time=5"])
    np.testing.assert_array_equal(base["posterior_cov"], moved["posterior_cov"])
    np.testing.assert_array_equal(base["transitions"], moved["transitions"])


SCALE_BIAS_FILTER = [
    "filter.scale_error=0.01", "filter.scale_error_std=0.02", "filter.bias=0.05", "filter.bias_std=0.1",
    "filter.reference_noise_std=0.2", "filter.sensor_noise_std=0.002", "filter.parameter_drift_std=0.0",
]


@pytest.mark.parametrize("drift", ["none", "random-walk"])
@pytest.mark.parametrize("name", [f.name for f in dataclasses.fields(ScaleBiasTruth)])
def test_scale_bias_filter_ignores_every_truth_setting(drift, name):
    """The scale/bias filter's gains depend on the data, so it is run on the same data: same output."""
    from kalcal.scenarios.scale_bias.filter import filter_scale_bias
    from kalcal.scenarios.scale_bias.simulation import sample_scale_bias

    assignments = [f"scenario.drift={drift}", "scenario.duration=5", *SCALE_BIAS_FILTER]
    scenario = build_scenario("scale-bias", None, assignments)
    data = sample_scale_bias(scenario, np.random.default_rng(2), 3)
    value = getattr(scenario.truth, name)
    new = 0.5 * value if name == "scale_error" else (1e-3 if value == 0 else 1.7 * value + 0.01)
    moved = build_scenario("scale-bias", None, [*assignments, f"truth.{name}={new!r}"])
    assert getattr(moved.truth, name) != value
    one = filter_scale_bias(scenario, data.reference, data.sensor)
    two = filter_scale_bias(moved, data.reference, data.sensor)
    for a, b in zip(one, two):
        np.testing.assert_array_equal(a, b)
