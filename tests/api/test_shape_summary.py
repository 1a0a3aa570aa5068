"""summary.json and the report carry the shape check: its family p-value, the worst update, the statistic
and its bound, for accel-gps fixes with Student-t noise (second moments the filter's)."""

from __future__ import annotations

import json

from kalcal.api.verification import compute_verification, save_verification
from kalcal.scenarios import build_scenario

STUDENT_T = ["scenario.truth=discrete", "truth.gps_noise=student-t", "truth.gps_noise_dof=5", "scenario.duration=10"]


def test_summary_and_report_carry_the_shape_check(tmp_path):
    scenario = build_scenario("accel-gps", None, STUDENT_T)
    run = compute_verification(scenario, 2000, 1)
    written = {test["name"]: test for test in json.loads(json.dumps(run.summary, default=str))["tests"]}
    shape = written["shape"]
    assert not shape["passed"] and shape["pvalue"] < 0.01
    assert shape["statistic"] > shape["upper"] > 0 and shape["lower"] is None
    assert [part["name"] for part in shape["parts"]] == ["nees", "nis"]
    assert all(part["upper"] > 0 and part["comparisons"] == 50 for part in shape["parts"])
    assert "at t = " in shape["detail"] and "NIS is not chi-square(2)" in shape["detail"]
    # the analysis sees the filter's second moments, but a Student-t truth is not the filter: no false alarm
    assert shape["cause"]["explained_by"] is None
    # the Gaussian fixes of the same run: the shape check passes
    gaussian = compute_verification(build_scenario("accel-gps", None, STUDENT_T[:1] + STUDENT_T[3:]), 2000, 1)
    assert {t["name"]: t for t in gaussian.summary["tests"]}["shape"]["passed"]

    save_verification(run, tmp_path, report=True)
    page = next(tmp_path.glob("*.html")).read_text(encoding="utf-8")
    assert '<a href="#fail-shape"><code>shape</code></a>' in page
