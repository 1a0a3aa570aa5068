"""Every scenario kalcal can build answers the Scenario protocol: the registry's built-in classes and a
model file's scenario (built from a file, so not in the registry's name-to-class table)."""

import dataclasses
from pathlib import Path

import pytest

from kalcal.scenarios import SCENARIOS, load_model_file
from kalcal.scenarios.protocol import Capabilities, Scenario

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
#: the example model files (examples/ also holds settings files, which are not scenarios)
MODEL_FILES = ("constant_velocity.toml", "constant_velocity_mistuned.toml", "accel_gps_colored_gps.toml")


def _scenarios():
    built_in = [(name, cls()) for name, cls in SCENARIOS.items()]
    files = [(name, load_model_file(EXAMPLES / name)) for name in MODEL_FILES]
    return built_in + files


@pytest.mark.parametrize("name, scenario", _scenarios(), ids=lambda v: v if isinstance(v, str) else "")
def test_each_scenario_answers_the_protocol(name, scenario):
    assert isinstance(scenario, Scenario), name
    assert isinstance(scenario.capabilities, Capabilities)
    assert scenario.capabilities.exact_analysis == bool(scenario.error_sources())
    assert isinstance(scenario.NAME, str) and scenario.NAME
    for command in ("simulate", "calibrate", "fit"):
        names = scenario.output_names(command) if command in scenario.capabilities.commands else None
        assert names is None or all(isinstance(n, str) for n in names)
    assert isinstance(scenario.source_report(), bool)
    pair = scenario.residual_pair_times()  # the report's pair of times, for its setup alone
    assert pair is None if not scenario.source_report() else (len(pair) == 2 and all(isinstance(t, float) for t in pair))
    for section in dataclasses.fields(scenario):  # what apply_settings changes: the section as given
        assert type(scenario.given_section(section.name)) is type(getattr(scenario, section.name))
    labels = scenario.state_labels  # one per filter state, or None: the problem's names say it
    if "verify" not in scenario.capabilities.commands:  # no Monte Carlo, no problem to name states (imu-3axis's calibrate)
        return
    d = len(scenario.problem(residual_pairs=False).info.state_names)
    assert labels is None or (len(labels) == d and all(isinstance(label, str) and label for label in labels))


def test_the_model_files_are_covered():
    """The parametrized test above reaches the model-file scenario, not only the registry's classes."""
    assert any(not isinstance(s, tuple(SCENARIOS.values())) for _, s in _scenarios())


def test_the_noise_filter_is_values_and_text_from_the_registry():
    """kalcal noise asks the registry for the [filter] it writes and gets values and text, not a scenario's
    module: the densities, their per-sample values at the log's rate, filter.toml naming its source."""
    import numpy as np

    from kalcal.calibration.noise import identify_noise
    from kalcal.scenarios import NoiseFilter, noise_filter

    rate = 100.0
    result = identify_noise(np.random.default_rng(0).normal(0.05, 0.02, 20_000), rate)
    written = noise_filter(result, "imu.csv")
    assert isinstance(written, NoiseFilter)
    assert written.settings["accel_noise_density"] > 0
    # per sample at the log's rate: accel_noise_std = N sqrt(rate)
    assert written.per_sample["rate"] == rate
    assert written.per_sample["accel_noise_std"] == pytest.approx(written.settings["accel_noise_density"] * np.sqrt(rate), rel=1e-12)
    assert "imu.csv" in written.toml and "[filter]" in written.toml
