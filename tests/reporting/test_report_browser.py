"""The page in a real browser: headless Chromium loads it offline and every figure decodes.

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


@pytest.mark.skipif(
    CHROMIUM is None and not IN_CI, reason="chromium is not installed (Debian's chromium package; CI installs it)"
)
def test_page_renders_in_headless_chromium_with_no_broken_image(chromium, report_run, tmp_path):
    out, page = report_run
    source = page.read_text(encoding="utf-8")
    probe = tmp_path / "probe.html"
    probe.write_text(source.replace("</body>", CHECK + "</body>"), encoding="utf-8")
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
        f"--user-data-dir={tmp_path / 'profile'}",
        "--virtual-time-budget=10000",
        "--dump-dom",
        probe.as_uri(),
    ]
    result = subprocess.run(command, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    match = re.search(r'<pre id="kalcal-image-check">(.*?)</pre>', result.stdout, re.S)
    assert match, f"the check script did not run; stderr: {result.stderr[-2000:]}"
    report = json.loads(html.unescape(match.group(1)))
    expected = len(list((out / "figures").glob("*.png")))
    assert report["count"] == expected == 18
    assert report["broken"] == []
    assert all(width == 900 for width in report["widths"])


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
