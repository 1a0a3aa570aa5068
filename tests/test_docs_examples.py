"""Every ```python (or ```py) block of the docs (docs/*.md and README.md) runs, so that the examples cannot rot."""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

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
