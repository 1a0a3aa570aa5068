"""Every ```python block of the docs (docs/*.md and README.md) runs, so that the examples cannot rot."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = sorted([*ROOT.glob("docs/*.md"), ROOT / "README.md"])
BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


def _blocks():
    for path in DOCS:
        for number, match in enumerate(BLOCK.finditer(path.read_text(encoding="utf-8")), start=1):
            yield pytest.param(match.group(1), id=f"{path.relative_to(ROOT)}#{number}")


def test_the_api_docs_have_examples():
    assert len([b for b in _blocks() if "docs/api.md" in b.id]) >= 5


@pytest.mark.parametrize("code", list(_blocks()))
def test_the_example_runs(code, tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)  # examples name files of the repository (examples/...)
    exec(compile(code, "<docs>", "exec"), {"__name__": "__docs__"})
    assert os.getcwd() == str(ROOT)
