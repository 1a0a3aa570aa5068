"""An unresolved latency is held at its input, what filter.toml runs, and the other free settings are
refitted there; with a Gauss-Markov bias in the model a free latency is not resolved at all."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pytest

import kalcal
from kalcal.scenarios.accel_gps.fit import fit_accel_gps
from kalcal.scenarios.accel_gps.latency_scan import MARKOV, NOT_RESOLVED, UNRESOLVED
from kalcal.scenarios import build_scenario

from tests.fitting.fake_log import FakeLog

ROVER = Path(__file__).resolve().parents[2] / "examples" / "rover-like.toml"
KEY = "filter.gps_latency"


@pytest.mark.parametrize("gate", [None, 0.999])
def test_the_other_settings_are_refitted_at_the_input_latency_and_log_l_is_the_written_points(gate):
    other = "filter.gps_velocity_std"
    knots = np.arange(-0.6, 0.6001, 0.005)  # a kink every 5 ms, as a noisy accelerometer's samples make
    bumps = np.random.default_rng(1).normal(0.0, 1.5, knots.size)
    # the other setting's best value moves with the latency: 0.05 (1 + 10 L)
    log = FakeLog(lambda v: -1e3 * (v[KEY] - 0.03) ** 2 + np.interp(v[KEY], knots, bumps)
                  - 1e4 * (v[other] - 0.05 * (1 + 10 * v[KEY])) ** 2,
                  np.random.default_rng(0).standard_normal((500, 2)), {KEY: 0.0, other: 0.04})
    result = fit_accel_gps(log, build_scenario("accel-gps", None, []), [KEY, other], gate=gate)
    p, q = result.parameters[KEY], result.parameters[other]
    assert not p.identified and p.held and p.note.startswith(UNRESOLVED)
    assert q.identified and not q.held and q.value == pytest.approx(0.05, abs=1e-4)  # the best at L = 0, not at L ~ 0.03 (0.065)
    written = {other: result.settings["filter"]["gps_velocity_std"]}
    assert result.settings["filter"]["gps_latency"] == 0.0
    assert result.loglik == pytest.approx(log.loglik(written), abs=1e-6)
    assert result.aic == pytest.approx(2.0 - 2.0 * result.loglik)
    assert KEY not in log.calls[-1] and log.calls[-1][other] == pytest.approx(0.05, abs=1e-4)
    # once the latency is held, calibrated at the written point only, not also at the discarded search's
    # (the gate's rounds before it calibrate at the searched latency, or at the start settings: {})
    assert [c for c in log.calls if c and KEY not in c] == [log.calls[-1]]
    assert any("refitted with filter.gps_latency at its input" in note for note in result.notes)
    assert result.adequate  # white unit innovations at the written point


#: less vibration than the example's 0.4 m/s^2: there the roughness rule passes
NOISE = {"truth.accel_noise_std": 0.1, "scenario.duration": 60}


@pytest.fixture(scope="module")
def markov_log():
    return kalcal.simulate("accel-gps", seed=0, config=ROVER, settings={"truth.gps_latency": 0.02, **NOISE})


def test_with_a_gauss_markov_bias_a_latency_the_roughness_rule_passes_is_not_resolved(markov_log):
    sim = markov_log
    result = kalcal.fit("accel-gps", imu=sim.logs["imu"], gps=sim.logs["gps"], config=ROVER,
                        settings={"truth.gps_latency": 0, **NOISE}, free=KEY)
    p = result.parameters[KEY]
    assert p.held and p.note.startswith(MARKOV), p.note  # not the roughness rule's note: that one passed
    assert not p.identified and p.value is None and p.ci_low is None and p.ci_high is None
    assert "coverage of its intervals with such a bias is not established" in p.note and p.note.startswith(NOT_RESOLVED)
    assert any(note.startswith(f"{KEY}: {MARKOV}") for note in result.notes)
    assert result.settings["filter"]["gps_latency"] == 0.0 and MARKOV in result.comments["gps_latency"]
    assert result.to_dict()["parameters"][KEY]["value"] is None


def test_the_terminal_table_says_not_resolved_and_fit_json_and_filter_toml_agree(markov_log, tmp_path):
    from typer.testing import CliRunner

    from kalcal.cli import app

    markov_log.save(tmp_path / "log")
    sets = [a for key, value in {"truth.gps_latency": 0, **NOISE}.items() for a in ("--set", f"{key}={value}")]
    out = tmp_path / "fit"
    run = CliRunner().invoke(app, ["fit", "accel-gps", "--imu", str(tmp_path / "log" / "imu.csv"), "--gps",
                                   str(tmp_path / "log" / "gps.csv"), "--config", str(ROVER), *sets, "--free", KEY,
                                   "--out", str(out)], catch_exceptions=False)
    assert run.exit_code == 0, run.stdout + run.stderr
    row = next(line for line in run.stdout.splitlines() if KEY in line and "input kept" in line)
    assert "not resolved" in row and "unidentified" not in row
    document = json.loads((out / "fit.json").read_text())
    assert document["parameters"][KEY]["identified"] is False and document["parameters"][KEY]["value"] is None
    text = (out / "filter.toml").read_text()
    assert tomllib.loads(text)["filter"]["gps_latency"] == 0.0 and MARKOV in text


def test_a_free_correlation_time_from_0_makes_the_model_gauss_markov_and_the_latency_not_resolved():
    tau = "filter.bias_correlation_time"
    # smooth in the latency (the roughness rule passes); the correlation time's start is 0 (a constant bias)
    std = "filter.bias_std"  # freed with the correlation time: a Gauss-Markov bias's stationary std
    log = FakeLog(lambda v: -1e3 * (v[KEY] - 0.02) ** 2 - (np.log(v[tau]) - np.log(30.0)) ** 2
                  - (np.log(v[std]) - np.log(0.1)) ** 2,
                  np.random.default_rng(0).standard_normal((500, 2)), {KEY: 0.0, tau: 0.0, std: 0.1})
    result = fit_accel_gps(log, build_scenario("accel-gps", None, []), [KEY, tau])
    assert result.parameters[KEY].note.startswith(MARKOV), result.parameters[KEY].note

