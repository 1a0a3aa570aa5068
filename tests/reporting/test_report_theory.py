"""The report's view of the exact analysis: the filter/exact/ensemble sigma figure, the exact column and
the self-check section, drawn by verify and redrawn by ``kalcal report`` from the settings."""

from __future__ import annotations

import base64
import json
import re

import numpy as np
import xarray as xr

from kalcal.reporting.render import render_report
from kalcal.scenarios import build_scenario
from kalcal.montecarlo.scenarios import build_problem
from kalcal.reporting.html import png_size
from kalcal.reporting.theory import SIGMA_EXACT_TITLE, self_check_section
from kalcal.stats.self_check import SELF_CHECK_PARTS, exact_prediction


def test_the_page_shows_filter_exact_and_ensemble_sigma(report_run):
    out, page_path = report_run
    page = page_path.read_text(encoding="utf-8")
    summary = json.loads((out / "summary.json").read_text())
    match = re.search(r'<figure id="fig-sigma_exact"><img src="data:image/png;base64,([A-Za-z0-9+/=]+)"', page)
    assert match and 'data-file="figures/sigma_exact.png"' in page and SIGMA_EXACT_TITLE.replace("'", "&#x27;") in page
    assert png_size(base64.b64decode(match.group(1))) == (900, 150 + 250 * 3)
    # the table's exact column is summary.json's P_true, which is the analysis of the rebuilt problem
    assert "exact σ = √P_true,ii" in page
    problem = build_problem(build_scenario("accel-gps", None, ["scenario.duration=6"]))[0]
    np.testing.assert_allclose(summary["final"]["exact_error_covariance"], exact_prediction(problem).error_cov[-1], rtol=1e-12)
    # the self-check, apart from the verdicts
    check = summary["self_check"]
    assert check["agrees"] is True
    section = page[page.index('<h2 id="self-check">') : page.index('<h2 id="figures">')]
    assert check["detail"] in section.replace("&#x27;", "'") and section.count("<td>agrees</td>") == len(SELF_CHECK_PARTS)


def test_report_redraws_the_figure_from_the_settings_alone(copy_run):
    """stats.nc holds no exact values (its variables are fixed): the redraw rebuilds them from the settings."""
    run = copy_run()
    assert not any(name.startswith("exact") for name in xr.open_dataset(run / "stats.nc").data_vars)
    page = render_report(run).read_text(encoding="utf-8")
    assert 'data-file="figures/sigma_exact.png"' in page and (run / "figures" / "sigma_exact.png").is_file()


def test_a_disagreeing_self_check_and_one_from_before_it():
    part = {"statistic": 7.5, "upper": 4.0, "comparisons": 90, "pvalue": 1e-10, "passed": False}
    check = {"agrees": False, "detail": "The ensemble departs from the exact analysis.", "reason": None,
             "parts": [{"name": "error_variance", **part}]}
    section = self_check_section({"self_check": check})
    assert "<td>DISAGREES</td>" in section and "The ensemble departs from the exact analysis." in section
    assert self_check_section({}) == ""


def test_the_page_shows_each_checks_power(report_run):
    """The power section: verify's power line and one row per check and part, its bracket and detection_n."""
    from kalcal.stats.power import power_line

    out, page_path = report_run
    page = page_path.read_text(encoding="utf-8")
    summary = json.loads((out / "summary.json").read_text())
    section = page[page.index('<h2 id="power">') : page.index('<h2 id="scenario">')]
    line = power_line(summary["power"], summary["realizations"], summary["power_reason"], summary["power_truth_equals_filter"])
    assert line.replace("'", "&#x27;") in section
    assert section.count("<tr><td>") == len(summary["power"])


def test_the_power_section_for_each_kind_of_summary():
    from kalcal.reporting.theory import power_section

    rows = [
        {"name": "mean_error", "part": None, "power_low": 0.001, "power_high": 0.004, "detectable": False, "detection_n": None},
        {"name": "covariance", "part": None, "power_low": 0.995, "power_high": 1.0, "detectable": True, "detection_n": 1234},
        {"name": "covariance", "part": "elements", "power_low": 0.5, "power_high": 0.5, "detectable": True, "detection_n": 1234},
    ]
    section = power_section({"realizations": 2000, "power": rows, "power_reason": None})
    assert "<td>mean_error</td><td>(whole check)</td><td class='num'>0.00</td><td class='num'>not detected</td>" in section
    assert "<td>covariance</td><td>(whole check)</td><td class='num'>0.99–1.00</td><td class='num'>1,234</td>" in section
    assert "<td>elements</td><td class='num'>0.50</td>" in section and "power at N = 2,000: verdict" in section
    none = power_section({"realizations": 2000, "power": None, "power_reason": "no exact analysis: the filter's gains depend on the data"})
    assert "power: not computed (no exact analysis: the filter&#x27;s gains depend on the data)" in none and "<table>" not in none
    assert power_section({"realizations": 2000}) == ""  # a summary from before the power
