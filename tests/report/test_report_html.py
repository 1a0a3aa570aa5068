"""The report page: self-contained, references every figure and check, leads failures with their cause."""

import base64
import json
import re

import pytest

from kalcal.report.figures import REPORT_NUMBERS, FigureEntry, SkippedFigure
from kalcal.report.html import build_page, png_size, shortfall, split_detail


def _failures_section(page: str) -> str:
    match = re.search(r'<section class="failures" id="failures">(.*?)</section>', page, re.S)
    assert match, "no failures section"
    return match.group(1)


def test_page_references_every_figure_and_check(report_run):
    out, page_path = report_run
    page = page_path.read_text(encoding="utf-8")
    summary = json.loads((out / "summary.json").read_text())
    files = sorted(p.name for p in (out / "figures").glob("*.png"))
    assert len(files) == 17  # 12 of the source report (5.6 as one two-panel file) + NEES, NIS, map, model error, steady state
    for name in files:
        assert f'data-file="figures/{name}"' in page
    for number in REPORT_NUMBERS.values():
        assert f"Figure {number}." in page
    for test in summary["tests"]:
        assert f'id="check-{test["name"]}"' in page
        assert f"<code>{test['name']}</code>" in page
    images = re.findall(r'<img src="data:image/png;base64,([A-Za-z0-9+/=]+)"', page)
    assert len(images) == len(files)
    for encoded in images:
        assert png_size(base64.b64decode(encoded))[0] == 900
    assert summary["command"] in page


def test_page_is_self_contained(report_run):
    page = report_run[1].read_text(encoding="utf-8")
    assert "<script" not in page.lower() and "<link" not in page.lower()
    assert not re.search(r"""(src|href)\s*=\s*["'](?!data:|#)""", page), "page loads something from outside"
    assert "http://" not in page and "https://" not in page


def test_failed_check_detail_leads_the_failures_section(report_run):
    out, page_path = report_run
    page = page_path.read_text(encoding="utf-8")
    summary = json.loads((out / "summary.json").read_text())
    failed = [t for t in summary["tests"] if not t["passed"]]
    assert any(t["name"] == "mean_error" for t in failed)  # Euler integration against the analytic truth
    section = _failures_section(page)
    assert page.index('class="failures"') < page.index('id="verdicts"')
    for test in failed:
        measured, cause = split_detail(test["detail"])
        assert f"Likely cause: {cause}" in section.replace("&#x27;", "'")
        assert section.index(cause[:40]) < section.index(measured[:40].replace("|", "|"))


def _summary(tests, **extra):
    base = {
        "scenario": "accel-gps",
        "settings": {"scenario": {"duration": 6.0}, "filter": {"bias_std": None}},
        "realizations": 100,
        "seed": 0,
        "engine": "exact",
        "confidence": 0.99,
        "tests": tests,
        "command": "kalcal verify -n 100 --set 'truth.bias_std=<0.1>'",
        "kalcal_version": "0.1.0",
    }
    return base | extra


def _test(name, passed, statistic, upper, detail, lower=None):
    return {"name": name, "passed": passed, "statistic": statistic, "lower": lower, "upper": upper,
            "confidence": 0.99, "comparisons": 10, "detail": detail}


def test_failure_says_what_by_how_much_and_why_escaped():
    tests = [
        _test("mean_error", False, 12.0, 4.0, "largest 12 standard errors (x<y & z). Explained by <Euler> integration"),
        _test("nis", False, 1.5, 2.1, "mean NIS 1.5. Innovations smaller than S", lower=1.9),
        _test("covariance", True, 1.0, 4.0, "fine"),
    ]
    page = build_page(_summary(tests), [], [])
    section = _failures_section(page)
    assert "Likely cause: Explained by &lt;Euler&gt; integration." in section
    assert "12 against an upper bound of 4: 8 above it (3 times the bound)" in section
    assert "1.5 against a lower bound of 1.9: 0.4 below it" in section
    assert "x&lt;y &amp; z" in section and "<Euler>" not in page and "x<y" not in page
    assert "covariance" not in section
    assert "&lt;0.1&gt;" in page and "not set (the truth&#x27;s value)" in page
    assert "2 of 3 checks failed" in section


def test_all_passed_has_no_failures_section():
    page = build_page(_summary([_test("nis", True, 2.0, 2.1, "mean NIS 2", lower=1.9)]), [], [])
    assert 'class="failures"' not in page and "Every check passed" in page


def test_skipped_figure_is_noted():
    skipped = [SkippedFigure("mean_error_long", "ensemble", "Longer run", "this run has no stats_long.nc", "5.8")]
    page = build_page(_summary([_test("nis", True, 2.0, 2.1, "ok")]), [], skipped)
    assert "Figure 5.8 (Longer run) is not shown:" in page and "stats_long.nc" in page


def test_shortfall_when_a_second_criterion_failed():
    text = shortfall(_test("covariance", False, 3.0, 4.0, "centered NEES out of bounds"))
    assert "within ≤ 4" in text


def test_split_detail():
    assert split_detail("measured 3.2 sd (t = 1 s). Cause: x. More") == ("measured 3.2 sd (t = 1 s)", "Cause: x. More")
    assert split_detail("only 2.5 units.") == ("only 2.5 units", "")


def test_figure_entry_embeds_png(tmp_path, report_run):
    png = next((report_run[0] / "figures").glob("nis.png"))
    entry = FigureEntry("nis", "consistency", "NIS <title>", "look & see", png)
    page = build_page(_summary([_test("nis", True, 2.0, 2.1, "ok")]), [entry], [])
    assert 'alt="NIS &lt;title&gt;"' in page and "look &amp; see" in page
    assert 'width="900" height="400"' in page


def test_png_size_rejects_other_files():
    with pytest.raises(ValueError):
        png_size(b"GIF89a" + bytes(30))


def test_figure_without_report_number_is_captioned_by_title(report_run):
    png = report_run[0] / "figures" / "nees.png"
    numbered = FigureEntry("mean_error", "ensemble", "Mean error", "look", png, "5.7")
    plain = FigureEntry("nees", "consistency", "Mean NEES", "look", png)
    page = build_page(_summary([_test("nis", True, 2.0, 2.1, "ok")]), [numbered, plain], [])
    assert "<strong>Figure 5.7. Mean error.</strong>" in page
    assert "<strong>Mean NEES.</strong>" in page
