"""``.ci/run``: installs Debian's chromium when it is missing and it may (root), then runs ``make test``.

The script runs against stand-ins for ``id``, ``apt-get`` and ``make`` on a PATH of their own, so
that nothing is installed and no test suite is started.
"""

import os
import shutil
import subprocess
from pathlib import Path

import pytest

from tests._helpers import ci_requested

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / ".ci" / "run"


def _stub(folder: Path, name: str, body: str) -> None:
    path = folder / name
    path.write_text(f"#!/bin/sh\n{body}\n")
    path.chmod(0o755)


def _run(tmp_path, *, uid: int, ci: str = "", chromium: bool = False, apt_installs: bool = True):
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    log = tmp_path / "log"
    for tool in ("dirname", "sh", "chmod"):
        os.symlink(shutil.which(tool), bin_dir / tool)
    _stub(bin_dir, "id", f'echo {uid}')
    make_chromium = f'printf "#!/bin/sh\\n" > "{bin_dir}/chromium"; chmod +x "{bin_dir}/chromium"' if apt_installs else ":"
    _stub(bin_dir, "apt-get", f'echo "apt-get $*" >> "{log}"; if [ "$1" = install ]; then {make_chromium}; fi')
    _stub(bin_dir, "make", f'echo "make $*" >> "{log}"')
    if chromium:
        _stub(bin_dir, "chromium", ":")
    env = {"PATH": str(bin_dir), "HOME": str(tmp_path), "CI": ci}
    result = subprocess.run([shutil.which("bash"), str(SCRIPT)], capture_output=True, text=True, env=env, timeout=60)
    calls = log.read_text().splitlines() if log.exists() else []
    return result, calls


def test_as_root_without_chromium_it_installs_it_then_tests(tmp_path):
    result, calls = _run(tmp_path, uid=0, ci="true")
    assert result.returncode == 0, result.stderr
    assert calls == ["apt-get update", "apt-get install -y --no-install-recommends chromium", "make test"]


def test_with_chromium_nothing_is_installed(tmp_path):
    result, calls = _run(tmp_path, uid=0, ci="true", chromium=True)
    assert result.returncode == 0, result.stderr
    assert calls == ["make test"]


def test_not_root_and_not_ci_it_leaves_the_browser_test_to_skip(tmp_path):
    result, calls = _run(tmp_path, uid=1000)
    assert result.returncode == 0, result.stderr
    assert calls == ["make test"]


def test_under_ci_without_root_a_missing_chromium_is_an_error(tmp_path):
    result, calls = _run(tmp_path, uid=1000, ci="true")
    assert result.returncode == 1 and calls == []
    assert "chromium is missing and installing it needs root" in result.stderr


def test_an_install_that_gives_no_chromium_stops_the_script_with_one_line(tmp_path):
    result, calls = _run(tmp_path, uid=0, ci="true", apt_installs=False)
    assert result.returncode == 1 and "make test" not in calls
    assert result.stderr.strip().splitlines()[-1] == ".ci/run: apt-get install chromium gave no chromium command on PATH"


def test_as_root_without_ci_it_still_installs_chromium(tmp_path):
    result, calls = _run(tmp_path, uid=0)
    assert result.returncode == 0, result.stderr
    assert calls == ["apt-get update", "apt-get install -y --no-install-recommends chromium", "make test"]


@pytest.mark.parametrize("value", ["true", "TRUE", "True", "1", "yes", ""])
def test_the_script_and_the_browser_test_read_ci_alike(tmp_path, value):
    """Not root and no chromium: the script refuses exactly when the browser test would fail for it."""
    result, calls = _run(tmp_path, uid=1000, ci=value)
    refused = result.returncode == 1 and calls == []
    assert refused == ci_requested(value), (value, result.stderr)
    if not refused:
        assert result.returncode == 0 and calls == ["make test"]


@pytest.mark.parametrize("line", ["set -euo pipefail", "make test"])
def test_the_script_stays_strict(line):
    assert line in SCRIPT.read_text().splitlines()


def test_the_readme_says_what_make_test_slow_runs():
    makefile = (ROOT / "Makefile").read_text()
    (recipe,) = [line for line in makefile.splitlines() if "pytest" in line and "slow" in line]
    assert recipe.rstrip().endswith("-m slow")  # only the slow tests, not the default suite as well
    readme = " ".join((ROOT / "README.md").read_text().split())
    assert "`make test-slow` runs only the tests marked slow" in readme
    assert "make test-slow` adds" not in readme
