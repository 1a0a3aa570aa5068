"""The report page: self-contained, references every figure and check, leads failures with their cause."""

import base64
import html
import json
import re

import pytest

from kalcal.reporting.figures import REPORT_NUMBERS, FigureEntry, SkippedFigure
from kalcal.reporting.html import png_size
from kalcal.reporting.html import build_page
from kalcal.reporting.text import measured_text, shortfall


def _failures_section(page: str) -> str:
    match = re.search(r'<section class="failures" id="failures">(.*?)</section>', page, re.S)
    assert match, "no failures section"
    return match.group(1)


def test_page_references_every_figure_and_check(report_run):
    out, page_path = report_run
    page = page_path.read_text(encoding="utf-8")
    summary = json.loads((out / "summary.json").read_text())
    files = sorted(p.name for p in (out / "figures").glob("*.png"))
    assert len(files) == 18  # 12 of the source report (5.6 as one two-panel file) + NEES, NIS, map, model error, steady state, exact sigma
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
    text = html.unescape(section)
    for test in failed:
        reason = test["cause"]["reason"]  # the cause as data, never split out of the detail
        assert reason and f"Likely cause: {reason.rstrip('.')}." in text
        measured = measured_text(test)
        assert test["detail"] == f"{measured}. {reason}"
        assert text.index(reason[:40]) < text.index(f"Measured:</strong> {measured}.")
    mean_error = next(t for t in failed if t["name"] == "mean_error")
    assert mean_error["cause"]["explained_by"] == "model_error"
    assert "Accounted for by:</strong> the mean error the filter's model predicts" in text


def test_header_states_each_checks_level_and_the_verdicts_bound(report_run):
    """Six checks at 99% each: a correct filter fails a given one with probability <= 1%, the verdict <= 6%."""
    page = html.unescape(report_run[1].read_text(encoding="utf-8"))
    assert "family-wise confidence" not in page
    statement = (
        "each check at 99% confidence (a correct filter fails it with probability at most 1%); a correct filter "
        "fails at least one of the 6 checks with probability at most 6% (Bonferroni)"
    )
    header = page[page.index("<h1>") : page.index("<nav>")]
    assert statement in header


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


def _test(name, passed, statistic, upper, detail, lower=None, reason=None, parts=(), **cause):
    return {"name": name, "passed": passed, "statistic": statistic, "lower": lower, "upper": upper,
            "pvalue": 0.5 if passed else 0.001, "confidence": 0.99, "comparisons": 10,
            "detail": detail if reason is None else f"{detail}. {reason}", "measured": detail,
            "cause": {"explained_by": cause.get("explained_by"), "direction": cause.get("direction"), "reason": reason},
            "parts": list(parts)}


def _part(name, passed, statistic, upper, lower=None):
    return {"name": name, "statistic": statistic, "pvalue": 0.5 if passed else 0.001, "lower": lower, "upper": upper,
            "confidence": 0.995, "alpha": 0.005, "comparisons": 10, "passed": passed}


def test_failure_says_what_by_how_much_and_why_escaped():
    tests = [
        _test("mean_error", False, 12.0, 4.0, "largest 12 standard errors (x<y & z)",
              reason="Explained by <Euler> integration", explained_by="model_error"),
        _test("nis", False, 1.5, 2.1, "mean NIS 1.5", lower=1.9, reason="Innovations smaller than S",
              direction="underconfident"),
        _test("covariance", True, 1.0, 4.0, "fine"),
    ]
    page = build_page(_summary(tests), [], [])
    section = _failures_section(page)
    assert "Likely cause: Explained by &lt;Euler&gt; integration." in section
    assert "Measured:</strong> largest 12 standard errors (x&lt;y &amp; z).</p>" in section
    assert "Direction:</strong> underconfident: the actual spread is smaller" in section
    assert "(p = 0.001 against 0.01)" in section
    assert "12 against an upper bound of 4: 8 above it (3 times the bound)" in section
    assert "1.5 against a lower bound of 1.9: 0.4 below it" in section
    assert "x&lt;y &amp; z" in section and "<Euler>" not in page and "x<y" not in page
    assert "covariance" not in section
    assert "&lt;0.1&gt;" in page and "not set (the truth&#x27;s value)" in page
    assert "2 of 3 checks failed" in section


def test_all_passed_has_no_failures_section():
    page = build_page(_summary([_test("nis", True, 2.0, 2.1, "mean NIS 2", lower=1.9)]), [], [])
    assert 'class="failures"' not in page and 'href="#failures"' not in page
    assert '<section class="answer pass" id="answer"><p class="verdict">Passes: all 1 checks' in page


def test_the_page_leads_with_its_answer_and_folds_the_detail(report_run):
    """The verdict's sentence, a row per check and the figures that show it come before every section;
    What failed, the full verdicts, the power table and the settings are folded."""
    out, page_path = report_run
    page = page_path.read_text(encoding="utf-8")
    summary = json.loads((out / "summary.json").read_text())
    answer = page.index('<section class="answer fail" id="answer">')
    checks = page.index('<table class="checks" id="checks">')
    lead = page.index('<div class="lead-figures">')
    assert page.index("<h1>") < answer < checks < lead < page.index("<nav>") < page.index('id="failures"')
    sentence = re.search(r'<p class="verdict">(.*?)</p>', page).group(1)
    assert html.unescape(sentence).startswith("Fails only through the known model error of the euler integration")
    # the model error's cause as the summary names it, not as the page writes it
    assert summary["model_error"]["cause"] in html.unescape(sentence)
    rows = re.findall(r"<tr class=\"(pass|fail)\"><td>(?:<a href=\"#fail-\w+\">)?<code>(\w+)</code>",
                      page[checks : page.index("</table>", checks)])
    assert [(name, state == "pass") for state, name in rows] == [(t["name"], t["passed"]) for t in summary["tests"]]
    figures = re.findall(r'<figure id="fig-(\w+)">', page[lead : page.index("<nav>")])
    assert figures == ["mean_error", "model_error", "nees", "nis"]
    for key in figures:  # shown once, linked from its group
        assert page.count(f'<figure id="fig-{key}">') == 1 and f'<a href="#fig-{key}">' in page
    for test in summary["tests"]:
        if not test["passed"]:
            assert f'<details id="fail-{test["name"]}"><summary><code>{test["name"]}</code>: ' in page
    assert "<details><summary>Statistic, bounds, levels and detail of each check</summary>" in page
    assert "<details><summary>Power of each check and part</summary>" in page
    assert f"<details><summary>All {sum(len(v) for v in summary['settings'].values())} settings</summary>" in page


def test_the_page_says_a_pass_is_about_the_filter_not_a_log():
    """A PASS is read as being about the log the settings came from: the page says what it tests, and
    points to fit's adequate."""
    from kalcal.reporting.text import scope_statement

    page = build_page(_summary([_test("nis", True, 2.0, 2.1, "mean NIS 2", lower=1.9)]), [], [])
    line = scope_statement()
    assert "synthetic motion" in line and "not against any log" in line and "`kalcal fit`'s `adequate`" in line
    assert f"<p class='scope'>{html.escape(line)}.</p>" in page


def test_skipped_figure_is_noted():
    skipped = [SkippedFigure("mean_error_long", "ensemble", "Longer run", "this run has no stats_long.nc", "5.8")]
    page = build_page(_summary([_test("nis", True, 2.0, 2.1, "ok")]), [], skipped)
    assert "Figure 5.8 (Longer run) is not shown:" in page and "stats_long.nc" in page


def test_shortfall_names_the_part_that_failed():
    parts = [_part("elements", True, 3.0, 4.0), _part("centered_nees", False, 3.2, 3.1, lower=2.9)]
    text = shortfall(_test("covariance", False, 3.0, 4.0, "centered NEES out of bounds", parts=parts))
    assert text == "centered NEES: 3.2 against an upper bound of 3.1: 0.1 above it (1.03 times the bound)"


def test_verdicts_table_shows_every_bound_and_pvalue():
    parts = [_part("elements", True, 3.0, 4.0), _part("centered_nees", False, 3.2, 3.1, lower=2.9)]
    page = html.unescape(build_page(_summary([_test("covariance", False, 3.0, 4.0, "d", parts=parts)]), [], []))
    assert "element-wise ≤ 4; centered NEES [2.9, 3.1]" in page
    assert ("99% confidence, 10 comparisons, p = 0.001; element-wise at 99.5%, 10 comparisons, p = 0.5; "
            "centered NEES at 99.5%, 10 comparisons, p = 0.001") in page


def test_measured_text_is_the_measured_field_never_cut_from_the_detail():
    test = _test("x", False, 1.0, 0.5, "measured 3.2 sd (t = 1 s)", reason="Cause: x. More")
    assert measured_text(test) == "measured 3.2 sd (t = 1 s)"
    # the field decides, not the detail's ending: a reason that ends the detail by chance stays in it
    assert measured_text(test | {"measured": test["detail"]}) == test["detail"].rstrip(".")
    # a summary written before the field: the whole detail, unparsed
    old = {k: v for k, v in test.items() if k != "measured"}
    assert measured_text(old) == "measured 3.2 sd (t = 1 s). Cause: x. More"
    assert measured_text(_test("x", False, 1.0, 0.5, "only 2.5 units. Then more.")) == "only 2.5 units. Then more"


def test_nan_pvalue_reads_not_computable_where_the_summary_counts_it():
    parts = [_part("elements", True, 3.0, 4.0) | {"pvalue": None}, _part("centered_nees", True, 3.0, 3.1, 2.9)]
    tests = [_test("covariance", False, None, 4.0, "no spread", parts=parts) | {"pvalue": None}]
    nonfinite = {"count": 3, "fields": {"tests.statistic": 1, "tests.pvalue": 1, "tests.parts.pvalue": 1}}
    page = html.unescape(build_page(_summary(tests, nonfinite=nonfinite), [], []))
    assert "p not recorded" not in page
    assert "10 comparisons, p = NaN (not computable); element-wise at 99.5%, 10 comparisons, p = NaN (not computable)" in page
    assert "(p = NaN (not computable) against 0.01)" in page
    # without the count (an older summary, or the key absent) the page does not claim a NaN
    assert "p not recorded" in html.unescape(build_page(_summary(tests), [], []))


@pytest.mark.parametrize("field", ["explained_by", "direction"])
def test_unknown_cause_value_is_an_error_not_dropped(field):
    from kalcal.errors import KalcalError

    test = _test("nis", False, 1.5, 2.1, "mean NIS 1.5", lower=1.9, reason="r", **{field: "sideways"})
    with pytest.raises(KalcalError, match=f"cause.{field}: unknown value 'sideways'"):
        build_page(_summary([test]), [], [])


def test_cause_words_cover_exactly_the_values_a_cause_takes():
    from kalcal.stats.results import DIRECTIONS, EXPLAINED_BY, Cause
    from kalcal.stats.text import direction_text, explained_by_text

    for value in EXPLAINED_BY:
        assert explained_by_text(Cause(explained_by=value).__dict__)
    for value in DIRECTIONS:
        assert direction_text(Cause(direction=value).__dict__)
    assert explained_by_text({}) is None and direction_text({"direction": None}) is None


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
