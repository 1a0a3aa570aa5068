"""The verify table at the command line: every part's bounds and the p-value, in the page's words."""

from __future__ import annotations

import io

import numpy as np
from rich.console import Console

from kalcal.cli import _common as cli
from kalcal.stats.nis import check_nis
from kalcal.stats.covariance import check_covariance
from kalcal.stats.text import check_bounds_text
from tests.stats.test_check_results import _info, _stats


def _printed(monkeypatch, tests, **extra) -> str:
    console = Console(width=200, record=True, file=io.StringIO())
    monkeypatch.setattr(cli, "console", console)
    summary = {
        "scenario": "synthetic", "realizations": 20000, "engine": "exact", "timing": {"monte_carlo_s": 1.0},
        "verdict": "fail", "tests": tests, **extra,
    }
    cli._print_checks(summary)
    return console.export_text()


def test_a_failure_of_the_centered_nees_alone_shows_its_bounds(monkeypatch):
    """C = 1.025 I3 against P = I3: the elements pass, the centered NEES fails; its bounds explain the FAIL."""
    s = _stats(20000, 1.025 * np.eye(3)[None], np.eye(3))
    covariance = check_covariance(s, _info(1, 3), 0.99).as_dict()
    elements, nees = covariance["parts"]
    assert elements["passed"] and not nees["passed"]
    text = _printed(monkeypatch, [covariance])
    (row,) = [line for line in text.splitlines() if line.startswith("│ covariance")]
    shown = f"element-wise ≤ {elements['upper']:.4g}; centered NEES [{nees['lower']:.4g}, {nees['upper']:.4g}]"
    assert shown == check_bounds_text(covariance) and shown in row
    assert "FAIL" in row and f"{covariance['pvalue']:.3g}" in row


def test_a_check_of_one_family_shows_its_own_bounds_and_a_nan_pvalue_says_so(monkeypatch):
    s = _stats(20000, np.eye(1)[None], np.eye(1))
    nis = check_nis(s, _info(1, 1), 0.99).as_dict()
    text = _printed(monkeypatch, [nis | {"pvalue": None, "statistic": None}], nonfinite={"fields": {"tests.pvalue": 1}})
    (row,) = [line for line in text.splitlines() if line.startswith("│ nis")]
    assert f"[{nis['lower']:.4g}, {nis['upper']:.4g}]" in row and "NaN (not computable)" in row
