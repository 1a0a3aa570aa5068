"""The page in a real browser: headless Chromium loads it offline, every figure decodes, and the answer
leads: the verdict's sentence and every lead figure (image and title) lie inside the first 1,200 pixels
at 1,400 px width.

Skipped when no ``chromium`` is on PATH (Debian's ``chromium`` package provides it), except under CI
(``CI=true``), where ``.ci/run`` installs it: there a missing browser is an error, not a skip.
"""

import html
import json
import os
import re
import shutil
import subprocess
import sys

import pytest

import kalcal
from tests._helpers import ci_requested

CHROMIUM = shutil.which("chromium")
IN_CI = ci_requested(os.environ.get("CI"))


@pytest.fixture(scope="session")
def chromium():
    """The browser's path; under CI its absence fails the test (before the run it would check is made)."""
    if CHROMIUM is None:
        pytest.fail("CI=true but chromium is not on PATH: .ci/run installs Debian's chromium package")
    return CHROMIUM

CHECK = """<script>
window.addEventListener("load", function () {
  var images = Array.prototype.slice.call(document.images);
  var broken = images.filter(function (img) { return !(img.complete && img.naturalWidth > 0); })
                     .map(function (img) { return img.getAttribute("data-file") || img.alt; });
  var out = document.createElement("pre");
  out.id = "kalcal-image-check";
  out.textContent = JSON.stringify({count: images.length, broken: broken,
                                    widths: images.map(function (img) { return img.naturalWidth; })});
  document.body.appendChild(out);
});
</script>
"""


needs_chromium = pytest.mark.skipif(
    CHROMIUM is None and not IN_CI, reason="chromium is not installed (Debian's chromium package; CI installs it)"
)


def _run_in_chromium(chromium, page, script, probe_id, tmp_path, window="1400,1200"):
    """Load ``page`` (a path) with ``script`` added before ``</body>`` in headless Chromium at a ``window``
    of width,height pixels, and return the JSON the script wrote into ``<pre id=probe_id>``."""
    source = page.read_text(encoding="utf-8")
    probe = tmp_path / f"{probe_id}.html"
    probe.write_text(source.replace("</body>", script + "</body>"), encoding="utf-8")
    command = [
        chromium,
        "--headless",
        "--no-sandbox",
        "--disable-dev-shm-usage",
        "--disable-gpu",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--no-first-run",
        f"--user-data-dir={tmp_path / f'profile-{probe_id}'}",
        f"--window-size={window}",
        "--virtual-time-budget=10000",
        "--dump-dom",
        probe.as_uri(),
    ]
    result = subprocess.run(command, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    match = re.search(rf'<pre id="{probe_id}">(.*?)</pre>', result.stdout, re.S)
    assert match, f"the check script did not run; stderr: {result.stderr[-2000:]}"
    return json.loads(html.unescape(match.group(1)))


@needs_chromium
def test_page_renders_in_headless_chromium_with_no_broken_image(chromium, report_run, tmp_path):
    out, page = report_run
    report = _run_in_chromium(chromium, page, CHECK, "kalcal-image-check", tmp_path)
    expected = len(list((out / "figures").glob("*.png")))
    assert report["count"] == expected == 18
    assert report["broken"] == []
    assert all(width == 900 for width in report["widths"])


#: where the verdict's sentence, the page's first figure and each lead figure (its image and its caption's
#: title, the whole ``<figure>``) lie, in CSS pixels from the page's top, once every image has loaded
#: (their width and height attributes fix the layout before they decode)
LAYOUT = """<script>
window.addEventListener("load", function () {
  function box(element) {
    if (!element) { return null; }
    var r = element.getBoundingClientRect();
    return {top: r.top + window.scrollY, bottom: r.bottom + window.scrollY, left: r.left, right: r.right};
  }
  var image = document.querySelector("figure img");
  var lead = Array.prototype.slice.call(document.querySelectorAll(".lead-figures figure")).map(function (f) {
    var img = f.querySelector("img");
    return {file: img.getAttribute("data-file"), loaded: img.complete && img.naturalWidth > 0,
            figure: box(f), image: box(img)};
  });
  var out = document.createElement("pre");
  out.id = "kalcal-layout";
  out.textContent = JSON.stringify({width: window.innerWidth, verdict: box(document.querySelector("#answer .verdict")),
                                    figure: box(image), file: image && image.getAttribute("data-file"),
                                    loaded: image && image.complete && image.naturalWidth > 0, lead: lead});
  document.body.appendChild(out);
});
</script>
"""
#: the first screen: the answer and every lead figure lie inside it, at the page's width
FIRST_SCREEN_PX, PAGE_WIDTH_PX = 1200, 1400


#: the figures that lead each page: the default run's failures root in the model error (its figures first),
#: the passing run's lead is the fill (mean error, covariance, innovations)
DEFAULT_LEAD = ["mean_error.png", "model_error.png", "nees.png", "nis.png"]
PASSING_LEAD = ["mean_error.png", "nees.png", "nis.png", "variance_diagonal.png"]


def _lead_files(page):
    """The file names of the figures in the page's lead row, read from its HTML."""
    source = page.read_text(encoding="utf-8")
    row = source[source.index('<div class="lead-figures">') : source.index("<nav>")]
    return re.findall(r'data-file="figures/([\w.]+)"', row)


def _inside_first_screen(what, box):
    assert 0 <= box["top"] < box["bottom"] <= FIRST_SCREEN_PX, (what, box)
    assert 0 <= box["left"] < box["right"] <= PAGE_WIDTH_PX, (what, box)


def _assert_first_screen(chromium, page, tmp_path, lead_figures):
    """The verdict and each of ``lead_figures`` (file names, in the page's order) inside the first screen."""
    layout = _run_in_chromium(chromium, page, LAYOUT, "kalcal-layout", tmp_path, f"{PAGE_WIDTH_PX},{FIRST_SCREEN_PX}")
    assert layout["width"] == PAGE_WIDTH_PX
    assert layout["verdict"] is not None, "no verdict sentence on the page"
    assert layout["figure"] is not None and layout["loaded"], "no figure on the page"
    assert layout["file"] == f"figures/{lead_figures[0]}"
    _inside_first_screen("verdict", layout["verdict"])
    _inside_first_screen("figure", layout["figure"])
    assert [f["file"] for f in layout["lead"]] == [f"figures/{name}" for name in lead_figures]
    for figure in layout["lead"]:
        assert figure["loaded"], figure["file"]
        _inside_first_screen(figure["file"], figure["figure"])  # the <figure> holds its image and title
        assert figure["figure"]["top"] <= figure["image"]["top"] < figure["image"]["bottom"] <= figure["figure"]["bottom"]
    return layout


@pytest.fixture(scope="module")
def default_report(tmp_path_factory):
    """The default run (accel-gps with its default settings: Euler against the analytic truth) at a smaller N."""
    out = tmp_path_factory.mktemp("default-run")
    kalcal.verify(n=20_000, seed=0, long_run=0, out=out, report=True)
    return out / "report.html"


@pytest.fixture(scope="module")
def passing_report(tmp_path_factory):
    """A run that passes: the same scenario integrated by the trapezoid rule, 6 s."""
    out = tmp_path_factory.mktemp("passing-run")
    settings = {"scenario.duration": 6, "scenario.integration": "trapezoid"}
    kalcal.verify(n=5_000, seed=3, settings=settings, long_run=0, out=out, report=True)
    return out / "report.html"


@needs_chromium
def test_the_default_runs_answer_and_first_figure_are_on_the_first_screen(chromium, default_report, tmp_path):
    assert 'class="answer fail"' in default_report.read_text(encoding="utf-8")
    layout = _assert_first_screen(chromium, default_report, tmp_path, DEFAULT_LEAD)
    print({f["file"]: (round(f["figure"]["top"]), round(f["figure"]["bottom"])) for f in layout["lead"]})


@needs_chromium
def test_a_passing_runs_answer_and_first_figure_are_on_the_first_screen(chromium, passing_report, tmp_path):
    assert 'class="answer pass"' in passing_report.read_text(encoding="utf-8")
    layout = _assert_first_screen(chromium, passing_report, tmp_path, PASSING_LEAD)
    print({f["file"]: (round(f["figure"]["top"]), round(f["figure"]["bottom"])) for f in layout["lead"]})


@pytest.mark.slow
@needs_chromium
def test_the_full_default_runs_answer_is_on_the_first_screen(chromium, tmp_path):
    """``kalcal verify`` as it runs by default (N = 300,000, with its long run): four checks fail."""
    kalcal.verify(out=tmp_path / "run", report=True)
    page = tmp_path / "run" / "report.html"
    assert "(4 of 5 checks fail)" in page.read_text(encoding="utf-8")
    lead = _lead_files(page)
    assert lead[:2] == ["mean_error.png", "model_error.png"] and len(lead) == 4, lead
    _assert_first_screen(chromium, page, tmp_path, lead)


@pytest.mark.parametrize("ci, outcome", [("true", "1 error"), ("", "1 skipped")])
def test_without_chromium_the_check_skips_but_fails_under_ci(tmp_path, ci, outcome):
    """Run the browser test with no chromium on PATH: a skip with its reason, or under CI an error."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTEST_")}
    env.update(PATH="", CI=ci)  # an empty PATH finds no chromium; python is called by its full path
    result = subprocess.run(
        [
            sys.executable, "-m", "pytest", __file__, "-q", "-p", "no:cacheprovider", "-p", "no:xdist",
            "-k", "headless_chromium", f"--basetemp={tmp_path / 'inner'}", "-rs",
        ],
        capture_output=True, text=True, timeout=300, env=env,
    )
    assert outcome in result.stdout, result.stdout[-3000:] + result.stderr[-2000:]
    if ci:
        assert result.returncode == 1 and "chromium is not on PATH" in result.stdout
    else:
        assert result.returncode == 0 and "chromium is not installed" in result.stdout
