"""``kalcal verify`` of a model file whose truth has states of its own ([truth] map): the coloured-GPS
example is found inconsistent, the report rebuilds without the file, a bad map is one line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from tests.test_cli_custom_model import EXAMPLES, _invoke, _verdicts, _verify

COLORED = EXAMPLES / "accel_gps_colored_gps.toml"

#: the constant-velocity tracker of constant_velocity.toml against a truth whose fixes carry a
#: Gauss-Markov error g (decay 0.95 per step, 2 m std): x_truth = [position, velocity, g]
TRACKER_TRUTH = """
[truth]
map   = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
state_names = ["position", "velocity", "fix_error"]
phi   = [[1.0, 0.1, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.95]]
gamma = [[0.005, 0.0], [0.1, 0.0], [0.0, 1.0]]
w     = [[0.04, 0.0], [0.0, 0.39]]
h     = [[1.0, 0.0, 1.0]]
v     = [[4.0]]
x0    = [0.0, 10.0, 0.0]
m0    = [[25.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 4.0]]
"""


def test_the_colored_gps_example_is_found_inconsistent(tmp_path):
    result = _verify(tmp_path, COLORED, "--no-report", "--seed", "7", n=2000)
    assert result.exit_code == 0, result.output + result.stderr
    assert "kalcal verify accel-gps-colored-gps" in result.output and "verdict: FAIL" in result.output
    verdicts = _verdicts(tmp_path)
    assert not verdicts["covariance"] and not verdicts["nis"] and not verdicts["residual_whiteness"]
    assert verdicts["mean_error"]  # unbiased: every prior mean is zero, only the uncertainty is wrong
    assert "overconfident" in result.output
    summary = json.loads((tmp_path / "summary.json").read_text())
    final = summary["final"]
    ratio = final["ensemble_covariance"][0][0] / final["filter_covariance"][0][0]
    assert ratio > 10.0, ratio  # the position error's variance: tens of times the filter's P at 30 s
    assert len(summary["settings"]["truth"]["map"]) == 3 and len(summary["settings"]["truth"]["phi"]) == 4
    assert summary["final"]["states"] == ["position", "velocity", "bias"]


def test_a_mapped_truths_report_rebuilds_without_the_file(tmp_path):
    model = tmp_path / "tracker.toml"
    model.write_text((EXAMPLES / "constant_velocity.toml").read_text() + TRACKER_TRUTH)
    out = tmp_path / "run"
    result = _verify(out, model, "--seed", "3", n=1000)
    assert result.exit_code == 0, result.output + result.stderr
    before = (out / "report.html").read_text()
    settings = json.loads((out / "summary.json").read_text())["settings"]
    assert settings["truth"]["map"] == [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    assert settings["truth"]["state_names"] == ["position", "velocity", "fix_error"]
    model.unlink()
    report = _invoke("report", out)
    assert report.exit_code == 0, report.output + report.stderr
    html = (out / "report.html").read_text()
    assert html == before  # the same settings and seed: the same page
    assert "<code>truth.map</code>" in html and "<code>truth.state_names</code>" in html
    assert np.isclose(settings["filter"]["w"][0][0], 0.04)


def test_a_bad_map_is_one_line_and_status_2(tmp_path):
    model = tmp_path / "tracker.toml"
    model.write_text((EXAMPLES / "constant_velocity.toml").read_text() + TRACKER_TRUTH.replace("gamma = [[0.005, 0.0], [0.1, 0.0], [0.0, 1.0]]\n", ""))
    result = _verify(tmp_path / "out", model, "--no-report", n=100)
    assert result.exit_code == 2 and result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"kalcal: error: {model}: truth.map: expected all of phi, gamma")
    assert lines[0].endswith("got no gamma"), lines[0]
