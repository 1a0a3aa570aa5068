"""The steady state on the report page, and the update form a run was verified with (--form).

The saved run of ``conftest.py`` is the accel-gps default, whose DARE has no stabilizing solution; the
scale-bias case (no steady state at all) is rendered into a copy of it with the view replaced, and the
stabilizing case (a constant-velocity tracker) into a page of its own, so that no second Monte Carlo is
needed.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

import kalcal.reporting.render as report_job
from kalcal.core.model import LinearGaussianModel
from kalcal.core.steps import covariance_pass
from kalcal.errors import ConfigError
from kalcal.filters.steady_state import SteadyStateView, convergence, steady_state
from kalcal.reporting.render import render_report
from kalcal.api.verification import verify
from kalcal.scenarios import build_scenario
from kalcal.montecarlo.scenarios import build_problem
from kalcal.plots.steady_state import plot_steady_state
from kalcal.reporting.figures import FigureEntry
from kalcal.reporting.html import build_page
from kalcal.reporting.steady_state import steady_state_view
from tests._helpers import assert_close, cov_atol


def _section(page: str) -> str:
    start = page.index('id="group-steady_state"')
    end = page.find("<h2", start)
    return page[start:end]


def test_default_run_says_there_is_no_stabilizing_solution(report_run):
    out, page_path = report_run
    section = _section(page_path.read_text(encoding="utf-8"))
    assert "No stabilizing solution:" in section and "mostly bias" in section
    assert 'id="fig-steady_state"' in section and "not stabilizing" in section
    assert (out / "figures" / "steady_state.png").is_file()
    assert re.search(r"<td>update form</td><td>joseph</td>", page_path.read_text(encoding="utf-8"))


def _tracker_view() -> SteadyStateView:
    model = LinearGaussianModel(
        phi=[[1.0, 0.5], [0.0, 1.0]], gamma=[[0.125], [0.5]], h=[[1.0, 0.0]], w=[[0.04]], v=[[1.0]],
        x0=[0.0, 0.0], m0=[[100.0, 0.0], [0.0, 25.0]], steps_per_update=2, sample_period=0.5,
    )
    schedule = covariance_pass(model, 200)
    result = steady_state(model)
    times = np.arange(1, 201) * 1.0
    return SteadyStateView(
        True, "", ("position", "velocity"), ("m", "m/s"), times, schedule.posterior_cov, result,
        convergence(schedule.posterior_cov, result.posterior_cov),
    )


def test_stabilizing_steady_state_is_tabled_beside_the_time_varying_filter(report_run, tmp_path):
    view = _tracker_view()
    assert view.result.exists and view.convergence.update is not None
    path = plot_steady_state(
        view.times,
        np.diagonal(view.posterior_cov, axis1=1, axis2=2),
        np.diagonal(view.result.posterior_cov),
        view.state_names,
        view.state_units,
        tmp_path / "steady_state.png",
        converged_time=view.converged_time(),
    )
    entry = FigureEntry("steady_state", "steady_state", "P_k against P∞", "caption", path)
    summary = json.loads((report_run[0] / "summary.json").read_text())
    section = _section(build_page(summary, [entry], [], steady_state=view))
    k = view.convergence.update
    assert f"from update {k + 1} of 200, t = {view.times[k]:.4g} s" in section
    assert "No stabilizing solution" not in section and 'id="fig-steady_state"' in section
    sigma = np.sqrt(view.result.posterior_cov[0, 0])
    assert f"<td class='num'>{sigma:.4g}</td>" in section
    for k_i in view.convergence.state_update:
        assert f"update {k_i + 1}, t = {view.times[k_i]:.4g} s" in section


def test_scale_bias_has_no_steady_state_and_the_page_says_why(copy_run, monkeypatch):
    problem, _ = build_problem(build_scenario("scale-bias", assignments=["scenario.duration=2"]))
    view = steady_state_view(problem)
    assert not view.applies and not view.has_matrices and "h_k = [z_k, 1]" in view.reason
    monkeypatch.setattr(report_job, "steady_state_view", lambda problem: view)
    run = copy_run(figures=True)  # a stale steady_state.png from an earlier rendering is removed
    section = _section(render_report(run).read_text(encoding="utf-8"))
    assert "is not shown:</strong> steady state does not apply: its measurement row h_k = [z_k, 1]" in section
    assert "<table>" not in section
    assert not (run / "figures" / "steady_state.png").exists()


def test_accel_gps_view_with_a_bias_walk_is_stabilizing():
    scenario = build_scenario("accel-gps", assignments=["scenario.duration=4", "truth.bias_walk_std=2e-4"])
    view = steady_state_view(build_problem(scenario)[0])
    assert view.applies and view.result.exists and view.convergence is not None
    assert view.convergence.update is None  # 20 updates are too few to settle


def test_accel_gps_with_a_scale_factor_state_is_not_time_invariant():
    scenario = build_scenario("accel-gps", assignments=["scenario.duration=2", "truth.scale_std=1e-3"])
    view = steady_state_view(build_problem(scenario)[0])
    assert not view.applies and "scale-factor" in view.reason


def test_verify_with_the_sqrt_form_gives_the_joseph_statistics(tmp_path):
    scenario = build_scenario("accel-gps", assignments=["scenario.duration=2"])
    joseph = verify(scenario, 300, 5, tmp_path / "joseph", long_run=0)
    sqrt = verify(scenario, 300, 5, tmp_path / "sqrt", long_run=0, form="sqrt")
    assert sqrt.summary["form"] == "sqrt" and joseph.summary["form"] == "joseph"
    a, b = joseph.ensemble, sqrt.ensemble
    assert_close(b.filter_cov, a.filter_cov, atol=cov_atol(a.filter_cov, 1e-9), what="filter covariance")
    assert_close(b.error_cov, a.error_cov, atol=cov_atol(a.error_cov, 1e-9), what="ensemble covariance")
    assert [t["passed"] for t in sqrt.summary["tests"]] == [t["passed"] for t in joseph.summary["tests"]]
    with pytest.raises(ConfigError, match="--form: expected one of joseph, standard, sqrt"):
        verify(scenario, 300, 5, tmp_path / "bad", long_run=0, form="cholesky")
    with pytest.raises(ConfigError, match="--form: 'sqrt' is not available for scale-bias"):
        verify(build_scenario("scale-bias"), 300, 5, tmp_path / "sb", form="sqrt")


def test_report_rebuilds_the_runs_form_and_refuses_an_unknown_one(copy_run):
    run = copy_run()
    summary = json.loads((run / "summary.json").read_text())
    summary["form"] = "qr"
    (run / "summary.json").write_text(json.dumps(summary))
    with pytest.raises(ConfigError, match=r"summary.json: form: expected one of joseph, standard, sqrt, got 'qr'"):
        render_report(run)
