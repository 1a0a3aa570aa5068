"""The sensitivity search: downward at large N to its floor, and the pairs only where they can decide."""

from __future__ import annotations

from pathlib import Path

import pytest

from kalcal.stats import sensitivity as module
from kalcal.analysis.fixed_gain import analyze_scenario
from kalcal.stats.suite import check_families
from kalcal.stats.sensitivity import FLOOR, RESOLUTION, START, detected_error, sensitivity, sensitivity_text
from kalcal.scenarios.model_file.model import load_model_file

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def test_large_n_searches_below_the_start():
    """At N = 2e6 every setting of constant_velocity.toml is detected below START (0.5%): each reported error
    is detected (pairs included) and one RESOLUTION step below it is not."""
    model = load_model_file(EXAMPLES / "constant_velocity.toml")
    n = 2_000_000
    rows = sensitivity(model, n)
    scaled = module.noise_settings(model)
    for row in rows:
        for key, sign in (("increase", 1.0), ("decrease", -1.0)):
            eps = row[key]
            assert FLOOR < eps < START, row
            assert module._detects(scaled[row["setting"]](1 + sign * eps), n, 0.99, "joseph")
            assert not module._detects(scaled[row["setting"]](1 + sign * eps / RESOLUTION), n, 0.99, "joseph")


def test_search_ends_at_the_floor_and_says_so():
    assert detected_error(lambda eps: True, 0.9) == FLOOR
    assert FLOOR <= detected_error(lambda eps: eps >= 1e-3, 0.9) <= 1e-3 * RESOLUTION
    assert detected_error(lambda eps: eps >= 1e-3, 0.9) >= 1e-3
    assert sensitivity_text({"setting": "truth.w", "increase": FLOOR, "decrease": FLOOR}) == "w ±≤0.01%"
    assert sensitivity_text({"setting": "truth.w", "increase": None, "decrease": FLOOR}) == "w −≤0.01%"


def test_whiteness_only_adds_power_so_the_search_without_pairs_bounds_it():
    """Without the pair moments the checks are those with them less residual_whiteness, brackets equal."""
    model = load_model_file(EXAMPLES / "constant_velocity.toml")
    scaled = module.noise_settings(model)["truth.v"](1.05)
    full = {c.name: c for c in check_families(analyze_scenario(scaled, pairs=True, budget=False))}
    cheap = {c.name: c for c in check_families(analyze_scenario(scaled, pairs=False, budget=False))}
    assert set(full) - set(cheap) == {"residual_whiteness"}
    for name, check in cheap.items():
        assert check.bracket(20_000) == full[name].bracket(20_000)


def test_pairs_are_rerun_once_unless_they_decide():
    calls = []

    def detects(threshold_with_pairs):
        def inner(eps, pairs):
            calls.append(pairs)
            return eps > (threshold_with_pairs if pairs else 0.03)

        return inner

    found = module._search(detects(0.03), 9.0)
    assert 0.03 < found <= 0.03 * RESOLUTION and calls.count(True) == 1
    calls.clear()
    found = module._search(detects(0.01), 9.0)  # the pairs detect a smaller error: searched with them
    assert 0.01 < found <= 0.01 * RESOLUTION and calls.count(True) > 1
    assert module._search(lambda eps, pairs: pairs and eps > 0.2, 9.0) == pytest.approx(0.2, rel=RESOLUTION - 1)
