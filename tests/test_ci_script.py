"""``.ci/run``: installs Debian's chromium when it is missing and it may (root), then runs ``make test``.

The script runs against stand-ins for ``id``, ``apt-get`` and ``make`` on a PATH of their own, so
that nothing is installed and no test suite is started.
"""

import os
import shutil
import subprocess
from pathlib import Path

import pytest

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
    assert calls == ["apt-get update", "apt-get install -y chromium", "make test"]


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


def test_an_install_that_gives_no_chromium_stops_the_script(tmp_path):
    result, calls = _run(tmp_path, uid=0, ci="true", apt_installs=False)
    assert result.returncode != 0 and "make test" not in calls


@pytest.mark.parametrize("line", ["set -euo pipefail", "make test"])
def test_the_script_stays_strict(line):
    assert line in SCRIPT.read_text().splitlines()
