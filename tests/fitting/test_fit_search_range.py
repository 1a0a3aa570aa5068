"""The latency's search range: +-max(0.5 s, |setting|) about 0, so that a setting beyond 0.5 s is inside it."""

from __future__ import annotations

import numpy as np
import pytest

from kalcal.scenarios.accel_gps.fit import fit_accel_gps
from kalcal.scenarios import build_scenario

from tests.fitting.fake_log import FakeLog

KEY = "filter.gps_latency"


@pytest.mark.parametrize("setting, reach", [(0.1, 0.5), (-0.8, 0.8)])
def test_the_latency_is_searched_within_the_larger_of_half_a_second_and_its_setting(setting, reach):
    log = FakeLog(lambda v: -1e4 * (v[KEY] - 0.03) ** 2, np.random.default_rng(0).standard_normal((500, 2)), {KEY: setting})
    result = fit_accel_gps(log, build_scenario("accel-gps", None, []), [KEY])
    values = result.curves[KEY]["value"]
    assert min(values) == pytest.approx(-reach) and max(values) == pytest.approx(reach)
    assert result.parameters[KEY].value == pytest.approx(0.03, abs=1e-4)
