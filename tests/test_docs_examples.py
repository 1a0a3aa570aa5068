"""Every ```python (or ```py) block of the docs (docs/*.md and README.md) runs, so that the examples cannot rot."""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = sorted([*ROOT.glob("docs/*.md"), ROOT / "README.md"])
BLOCK = re.compile(r"^```(?:python|py)[ \t]*\n(.*?)^```", re.S | re.M)
#: every opening fence of a Python block, counted apart from BLOCK so that none is skipped unseen
FENCE = re.compile(r"^```(?:python|py)\b", re.M)


def _blocks_of(path: Path) -> list[str]:
    return [match.group(1) for match in BLOCK.finditer(path.read_text(encoding="utf-8"))]


def _blocks():
    for path in DOCS:
        for number, code in enumerate(_blocks_of(path), start=1):
            yield pytest.param(code, id=f"{path.relative_to(ROOT)}#{number}")


def test_the_api_docs_have_examples():
    assert len([b for b in _blocks() if "docs/api.md" in b.id]) >= 5


@pytest.mark.parametrize("path", DOCS, ids=[str(path.relative_to(ROOT)) for path in DOCS])
def test_every_python_fence_is_a_block_that_runs(path):
    assert len(_blocks_of(path)) == len(FENCE.findall(path.read_text(encoding="utf-8")))


@pytest.mark.parametrize("code", list(_blocks()))
def test_the_example_runs(code, tmp_path, monkeypatch):
    # examples name files of the repository (examples/...): they run in a copy, so the tree stays clean
    shutil.copytree(ROOT / "examples", tmp_path / "examples")
    monkeypatch.chdir(tmp_path)
    exec(compile(code, "<docs>", "exec"), {"__name__": "__docs__"})
    assert os.getcwd() == str(tmp_path)


# --- the README's shell commands: every one names options its command has, and the first run and the
# quick start print what the README quotes (docs/glossary.md and the README state these numbers)

SH = re.compile(r"^ *```sh[ \t]*\n(.*?)^ *```", re.S | re.M)
TEXT = re.compile(r"^ *```text[ \t]*\n(.*?)^ *```", re.S | re.M)
README = ROOT / "README.md"


def _section(title: str) -> str:
    """The README's text from the heading ``## title`` to the next ``## ``."""
    text = README.read_text(encoding="utf-8")
    start = text.index(f"\n## {title}")
    end = text.find("\n## ", start + 1)
    return text[start : end if end > 0 else None]


def _commands(text: str) -> list[list[str]]:
    """The ``kalcal ...`` commands of the ```sh blocks of ``text``, comments dropped, ``&&`` split."""
    commands = []
    for block in SH.findall(text):
        for line in block.splitlines():
            for part in line.split("#", 1)[0].split("&&"):
                words = shlex.split(part)
                if words and words[0] == "kalcal":
                    commands.append(words[1:])
    return commands


def _kalcal(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    # 80 columns: the width the README's quoted tables were printed at
    return subprocess.run([sys.executable, "-m", "kalcal", *args], cwd=cwd, capture_output=True, text=True,
                          env={**os.environ, "COLUMNS": "80"}, timeout=600)


def test_the_readme_lists_every_kind_of_scenario_with_a_command():
    """Its command list runs each built-in by name, a model file and a model written as code; its
    scenario list names each."""
    from kalcal.scenarios import is_code_model, is_model_file, scenario_names

    given = {args[1] for args in _commands(_section("Commands")) if len(args) > 1 and not args[1].startswith("-")}
    kinds = {name: name in given for name in scenario_names()}
    kinds["a model file"] = any(is_model_file(arg) for arg in given)
    kinds["a model written as code"] = any(is_code_model(arg) for arg in given)
    assert all(kinds.values()), kinds
    listed = _section("Scenarios")
    assert all(f"**{name}**" in listed for name in scenario_names()) and "written as code" in listed


def test_every_readme_command_names_a_command_and_options_it_has(tmp_path):
    commands = _commands(README.read_text(encoding="utf-8"))
    assert len(commands) >= 15
    helps: dict[str, str] = {}
    for args in commands:
        name = args[0] if args and not args[0].startswith("-") else "verify"
        if name not in helps:
            result = _kalcal([name, "--help"], tmp_path)
            assert result.returncode == 0, (name, result.stderr)
            helps[name] = result.stdout
        for word in args:
            if word.startswith("--"):
                assert word.split("=")[0] in helps[name], (args, word)


def _quoted_lines(text: str) -> list[str]:
    """The README's quoted output lines; a line cut with ``...`` stands for its part before the cut."""
    lines = []
    for block in TEXT.findall(text):
        for line in block.splitlines():
            line = line.strip().split("...")[0].rstrip()
            if line:
                lines.append(re.sub(r" in [0-9.]+ s,", " in <t> s,", line))
    return lines


def _assert_quoted(text: str, output: str) -> None:
    output = re.sub(r" in [0-9.]+ s,", " in <t> s,", output)
    missing = [line for line in _quoted_lines(text) if line not in output]
    assert not missing, missing


@pytest.mark.slow
def test_the_readme_first_run_fails_as_quoted_and_its_two_remedies_pass(tmp_path):
    section = _section("What the first run shows")
    remedies = _commands(section)  # the first run itself is `make run`, which is `kalcal verify`
    assert len(remedies) == 2 and all(args[0] == "verify" for args in remedies)
    result = _kalcal(["verify", "--out", "first"], tmp_path)
    assert result.returncode == 0, result.stderr
    _assert_quoted(section, result.stdout)
    assert "verdict: FAIL" in result.stdout  # the quoted title line is cut before its time (it varies by machine)
    assert "largest in filter sigma 1.99 sigma (velocity at t = 30 s)" in " ".join(result.stdout.split())
    for number, args in enumerate(remedies):
        result = _kalcal([*args, "--out", f"remedy{number}"], tmp_path)
        assert result.returncode == 0 and "verdict: PASS" in result.stdout, (args, result.stdout[-2000:])


@pytest.mark.slow
def test_the_readme_quick_start_runs_and_prints_what_it_quotes(tmp_path):
    shutil.copytree(ROOT / "examples", tmp_path / "examples")
    section = _section("Quick start")
    commands = _commands(section)
    assert [args[:2] for args in commands] == [
        ["simulate", "accel-gps"], ["calibrate", "accel-gps"], ["fit", "accel-gps"], ["calibrate", "accel-gps"]]
    output = ""
    for args in commands:
        result = _kalcal(args, tmp_path)
        assert result.returncode == 0, (args, result.stderr)
        output += result.stdout + result.stderr
    _assert_quoted(section, output)
    flat = " ".join(output.split())
    assert "bias │ -0.0394177 │ 8.34e-05 NOT trusted" in flat
    assert "adequate: yes: noise settings consistent with the data" in flat
    # the prose: bias = -0.0085 ± 0.031 m/s^2 against the true final bias 0.0113, 0.6 sigma away
    summary = json.loads((tmp_path / "cal2" / "summary.json").read_text())
    truth = pd.read_csv(tmp_path / "rover" / "truth.csv")["bias"].iloc[-1]
    sigma = summary["settings_sigma"]["bias_std"]
    assert (round(summary["bias"], 4), round(sigma, 3), round(truth, 4)) == (-0.0085, 0.031, 0.0113)
    assert summary["sigma_trusted"] and summary["stability"]["stable"]
    assert round(abs(summary["bias"] - truth) / sigma, 1) == 0.6
