"""The API returns a nonlinear run's effect sizes, Cramér–Rao rows and power by simulation typed
(:mod:`kalcal.results.effects`), the same numbers as summary.json's sections, and None where a run has none."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import kalcal
from kalcal.results.effects import CramerRaoState, CramerRaoSummary, PowerBySimulation, RunEffectSizes
from kalcal.scenarios.nonlinear.power import PowerRow
from kalcal.stats.effects import EffectSize

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "range_bearing.py"


@pytest.fixture(scope="module")
def result():
    return kalcal.verify(str(EXAMPLE), n=300, seed=1, long_run=0,
                         settings={"scenario.updates": 8, "checks.power_runs": 1, "filter.compiled": "no"})


def test_effect_sizes_are_typed_and_the_summarys(result):
    effects, raw = result.effect_sizes, result.summary["effect_sizes"]
    assert isinstance(effects, RunEffectSizes)
    assert effects.verdict == raw["verdict"] in ("pass", "fail", "undecided") and effects.tolerance == 0.1
    assert all(isinstance(e, EffectSize) for e in effects.overall)
    assert [e.as_dict() for e in effects.overall] == raw["overall"]
    assert effects.per_update["variance_ratio"].shape == (8, 4, 3)  # value, lower, upper per update and state
    ratio = effects.per_update["variance_ratio"]
    assert np.all((ratio[..., 1] <= ratio[..., 0]) & (ratio[..., 0] <= ratio[..., 2]))
    np.testing.assert_array_equal(effects.per_update["nees_per_dim"], raw["per_update"]["nees_per_dim"])


def test_cramer_rao_rows_are_typed_and_the_summarys(result):
    crb, raw = result.cramer_rao, result.summary["cramer_rao"]
    assert isinstance(crb, CramerRaoSummary) and crb.available
    assert [r.state for r in crb.final] == ["px", "py", "vx", "vy"]
    row = crb.state("vx")
    assert isinstance(row, CramerRaoState) and row.unit == "(m/s)^2"
    assert row.lower_bound == raw["final"][2]["lower_bound"] and row.efficiency == row.lower_bound / row.mse
    assert crb.bound_diagonal.shape == crb.mse.shape == crb.mse_se.shape == (8, 4)
    with pytest.raises(KeyError, match="px"):
        crb.state("speed")


def test_power_by_simulation_is_typed_and_the_summarys(result):
    power, raw = result.power_by_simulation, result.summary["power_by_simulation"]
    assert isinstance(power, PowerBySimulation) and power.runs == 1 and power.realizations == 300
    assert set(power.alternatives) == {"null", "R x 1.5", "P x 0.8", "bias 0.2 sigma"}
    assert all(isinstance(r, PowerRow) for r in power.rows) and len(power.rows) == len(raw["rows"])
    row = power.rate("R x 1.5", "nis")
    assert 0.0 <= row.exact_lower <= row.exact_rate <= row.exact_upper <= 1.0
    with pytest.raises(KeyError):
        power.rate("R x 9", "nis")


def test_a_section_the_run_lacks_is_none():
    linear = kalcal.verify("scale-bias", n=200, seed=1, long_run=0)
    assert linear.effect_sizes is None and linear.cramer_rao is None and linear.power_by_simulation is None
    no_power = kalcal.verify(str(EXAMPLE), n=200, seed=1, long_run=0,
                             settings={"scenario.updates": 4, "filter.compiled": "no"})
    assert no_power.power_by_simulation is None and isinstance(no_power.effect_sizes, RunEffectSizes)
