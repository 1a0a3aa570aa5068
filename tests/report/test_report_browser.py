"""The page in a real browser: headless Chromium loads it offline and every figure decodes.

Skipped when no ``chromium`` is on PATH (Debian's ``chromium`` package provides it).
"""

import html
import json
import re
import shutil
import subprocess

import pytest

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


@pytest.mark.skipif(shutil.which("chromium") is None, reason="chromium is not installed")
def test_page_renders_in_headless_chromium_with_no_broken_image(report_run, tmp_path):
    out, page = report_run
    source = page.read_text(encoding="utf-8")
    probe = tmp_path / "probe.html"
    probe.write_text(source.replace("</body>", CHECK + "</body>"), encoding="utf-8")
    command = [
        shutil.which("chromium"),
        "--headless",
        "--no-sandbox",
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
    assert report["count"] == expected == 17
    assert report["broken"] == []
    assert all(width == 900 for width in report["widths"])
