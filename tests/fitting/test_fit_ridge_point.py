"""Settings that trade off along a ridge of log L: fit.json says only their combination is identified
(value null), while the fitted filter, filter.toml and the adequacy check use the fitted point on the
ridge, not the input settings, which lie off it."""

from __future__ import annotations

import numpy as np
import pytest

from kalcal.scenarios.accel_gps.fit import fit_accel_gps
from kalcal.scenarios import build_scenario

from tests.fitting.fake_log import FakeLog

A, B = "filter.gps_position_std", "filter.gps_velocity_std"


def test_ridge_members_are_unidentified_in_fit_json_but_the_filter_runs_at_the_fitted_point():
    x = np.random.default_rng(5).normal(0.0, 1.0, 300)
    s2 = float(np.mean(x**2))

    def loglik(v):  # depends on the two only through their sum: a ridge
        sigma = v[A] + v[B]
        return -x.size * (np.log(sigma) + 0.5 * s2 / sigma**2)

    log = FakeLog(loglik, np.random.default_rng(0).standard_normal((300, 2)), {A: 0.3, B: 0.4})
    result = fit_accel_gps(log, build_scenario("accel-gps", None, []), [A, B])
    a, b = result.parameters[A], result.parameters[B]
    assert not a.identified and a.value is None and a.as_dict()["value"] is None and not b.identified
    assert "trades off with" in a.note and "only their combination is identified" in a.note
    written = result.settings["filter"]
    total = written["gps_position_std"] + written["gps_velocity_std"]
    assert total == pytest.approx(np.sqrt(s2), rel=1e-4)  # on the ridge, not the inputs' 0.7
    best = loglik({A: np.sqrt(s2), B: 0.0})  # the ridge's log L, in closed form
    assert loglik({A: written["gps_position_std"], B: written["gps_velocity_std"]}) == pytest.approx(best, abs=1e-3)
    assert loglik({A: 0.3, B: 0.4}) < best - 1.92  # the inputs are off the ridge
    assert log.calls[-1][A] + log.calls[-1][B] == pytest.approx(np.sqrt(s2), rel=1e-4)  # adequacy judged there
    assert "only their combination is identified" in result.comments["gps_position_std"]
