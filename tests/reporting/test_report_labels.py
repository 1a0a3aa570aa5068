"""What the page says: error states by their symbols, the NEES the check tests, a wall time that says
what it covers, and the report's E[r_k r_j^T] pair only where the run has it."""

import json

from kalcal.reporting.html import residual_pair_table


def test_realization_figures_name_the_error_states(report_run):
    page = report_run[1].read_text(encoding="utf-8")
    assert "True and estimated velocity state δv = v − v_c, realization 4321" in page
    assert "True and estimated position state δp = p − p_c, realization 4321" in page
    assert "True and estimated bias state b, realization 4321" in page
    assert "the error state δv = v − v_c of the nominal that the accelerometer integrates, not the velocity itself" in page


def test_nees_figure_is_the_covariance_checks_statistic(report_run):
    page = report_run[1].read_text(encoding="utf-8")
    assert "Centered mean NEES (the covariance check&#x27;s statistic) and mean NEES against time" in page


def test_the_wall_time_says_what_it_covers(report_run):
    page = report_run[1].read_text(encoding="utf-8")
    assert "total wall time of kalcal verify" not in page
    assert "wall time of the verification up to summary.json: Monte Carlo, long run, checks, statistics files; not the report (s)" in page


def test_the_residual_pair_section_only_where_the_run_has_the_pair(report_run):
    out, page_path = report_run
    summary = json.loads((out / "summary.json").read_text())
    assert summary["residual_correlation"] is None  # a 6 s run has no update at 23.8 s
    assert "E[r_k r_jᵀ] at t_k" not in page_path.read_text(encoding="utf-8")
    summary["residual_correlation"] = {
        "k_time": 23.8,
        "j_time": 5.8,
        "matrix": [[1.5e-6, -2e-7], [3e-9, 4e-8]],
        "correlation": [[0.01, -0.02], [0.003, 0.04]],
        "standard_error": [[2e-6, 3e-7], [3e-7, 5e-8]],
    }
    assert residual_pair_table({"residual_correlation": None}) == ""
    page = residual_pair_table(summary)
    assert "E[r_k r_jᵀ] at t_k = 23.8 s, t_j = 5.8 s" in page and "1.5e-06 ± 2e-06" in page
