"""How a fit's parametric bootstrap is shown: fit-bootstrap.png's panels, the terminal table's "not applicable"
row, and the likelihood interval beside the bootstrap's in ``summary()`` and ``_repr_html_``.

The model and logs are test_bootstrap's AR(1) (w, v fitted; truths 1 and 2). Two fits of it, B = 19 at 90%
(the fewest replicates that level allows):

* a 150-row log (seed 11): both settings interior, each one's refits and intervals within a decade;
* a 50-row log (seed 1004, the first of test_bootstrap's SHORT_SEEDS whose w is at its bound, asserted here):
  w consistent with 0, its percentile interval not applicable, its refits down to the search floor.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from kalcal.fitting.run import FitOptions
from kalcal.scenarios.model_file.fit import fit_model_file
from kalcal.scenarios.model_file.model import parse_model
from tests.fitting.test_bootstrap import AR1, _log

AT_BOUND_SEED = 1004


def _boot(scenario, log, free=None):
    return fit_model_file(scenario, log, free=free, confidence=0.9,
                          options=FitOptions(bootstrap=19, seed=3, threads=2, confidence=0.9))


@pytest.fixture(scope="module")
def ar1():
    return parse_model(AR1, "ar1.toml")


@pytest.fixture(scope="module")
def interior(ar1):
    result = _boot(ar1, _log(150, 11))
    assert all(b.applicable and b.ci_low is not None and b.ci_high is not None for b in result.bootstrap.parameters.values())
    return result


@pytest.fixture(scope="module")
def at_bound(ar1):
    result = _boot(ar1, _log(50, AT_BOUND_SEED))
    assert result.parameters["filter.w"].at_bound and not result.bootstrap.parameters["filter.w"].applicable
    return result


def _panels(result):
    from kalcal.plots.fit import bootstrap_figure

    figure = bootstrap_figure(result)
    figure.canvas.draw()  # the tick labels are the formatters' only once the figure is laid out
    return [ax for ax in figure.axes if ax.get_visible()]


def _numbers(ax) -> list[str]:
    """The x tick labels within the axis's limits that hold a number (major and minor ticks)."""
    low, high = sorted(ax.get_xlim())
    shown = []
    for locs, formatter in ((ax.xaxis.get_majorticklocs(), ax.xaxis.get_major_formatter()),
                            (ax.xaxis.get_minorticklocs(), ax.xaxis.get_minor_formatter())):
        locs = [loc for loc in locs if low <= loc <= high]
        shown += [text for text in formatter.format_ticks(locs) if re.search(r"\d", text)]
    return shown


def _lines(ax, gid: str) -> list[float]:
    return sorted(float(np.asarray(line.get_xdata())[0]) for line in ax.get_lines() if line.get_gid() == gid)


# One panel per free setting, in order; each x axis has numbered ticks within its limits (the interior fit's
# refits span less than a decade: a log axis there had no decade tick and its minor labels were blanked, so
# no number at all); the likelihood interval's ends are lines at the fit's ci_low/ci_high, the percentile
# interval's at the bootstrap's.
def test_every_panel_has_numbers_and_the_likelihood_interval(interior):
    panels = _panels(interior)
    spans = [max(b.values) / min(b.values) for b in interior.bootstrap.parameters.values()]
    assert min(spans) < 10, spans  # v's: the case a log axis cannot number
    assert [ax.get_title().split(":")[0] for ax in panels] == list(interior.parameters) == ["filter.w", "filter.v"]
    for ax, (name, p) in zip(panels, interior.parameters.items()):
        b = interior.bootstrap.parameters[name]
        assert len(_numbers(ax)) >= 2, (name, ax.get_xscale(), ax.get_xlim(), _numbers(ax))
        assert _lines(ax, "likelihood-interval") == pytest.approx([p.ci_low, p.ci_high], rel=1e-12)
        assert _lines(ax, "percentile-interval") == pytest.approx([b.ci_low, b.ci_high], rel=1e-12)
        low, high = ax.get_xlim()
        assert low <= min(b.values) and max(b.values) <= high and low <= p.ci_low and p.ci_high <= high


# w at its bound: its panel says "not applicable" and why, draws no percentile lines, keeps the refits (down to
# the search floor, six decades: a log axis, numbered by its decades) and the likelihood interval's upper end
# (its lower end, 0, is off a log axis: the band runs from the axis's left); v's panel is as in the interior fit.
def test_a_setting_at_its_bound_has_a_panel_saying_not_applicable(at_bound):
    w_ax, v_ax = _panels(at_bound)
    w, v = at_bound.parameters["filter.w"], at_bound.parameters["filter.v"]
    assert "not applicable" in w_ax.get_title() and "at its lower bound (consistent with 0)" in w_ax.get_title()
    assert w_ax.get_xscale() == "log" and min(at_bound.bootstrap.parameters["filter.w"].values) < 1e-5
    assert len(_numbers(w_ax)) >= 2, (w_ax.get_xlim(), _numbers(w_ax))
    assert _lines(w_ax, "percentile-interval") == []
    assert _lines(w_ax, "likelihood-interval") == pytest.approx([w.ci_high], rel=1e-12) and w.ci_low == 0
    assert "not applicable" not in v_ax.get_title() and len(_numbers(v_ax)) >= 2
    assert _lines(v_ax, "likelihood-interval") == pytest.approx([v.ci_low, v.ci_high], rel=1e-12)


# A setting held in every refit (w unidentified: gamma = 0, the process noise never reaches the state) has a
# panel too, saying "not applicable" and why, beside v's histogram.
def test_a_held_setting_has_a_panel_saying_why(ar1):
    blind = parse_model(AR1.replace("gamma = [[1.0]]", "gamma = [[0.0]]"), "blind.toml")
    result = _boot(blind, _log(150, 11), free=["filter.w", "filter.v"])
    assert not result.parameters["filter.w"].identified
    w_ax, v_ax = _panels(result)
    assert w_ax.get_title() == "filter.w: not applicable"
    assert any("unidentified" in text.get_text() for text in w_ax.texts)
    assert len(_numbers(v_ax)) >= 2


# The terminal table, end to end: a log whose w is at its bound prints w's row as "not applicable" with the
# reason (Andrews 2000), beside its likelihood interval [0, upper]; v's row has its percentile interval.
def test_the_cli_table_says_not_applicable_with_the_reason(tmp_path, monkeypatch):
    from rich.console import Console
    from typer.testing import CliRunner

    import kalcal.cli._common as common
    from kalcal.cli import app

    (tmp_path / "ar1.toml").write_text(AR1)
    _log(50, AT_BOUND_SEED).to_csv(tmp_path / "y.csv", index=False)
    # wide enough that the reason is not folded across lines (the console is made once per process)
    monkeypatch.setattr(common, "console", Console(width=400), raising=False)
    done = CliRunner().invoke(app, ["fit", str(tmp_path / "ar1.toml"), "--data", str(tmp_path / "y.csv"), "--bootstrap",
                                    "39", "--seed", "2", "--threads", "2", "--out", str(tmp_path / "out")])
    assert done.exit_code == 0, done.output
    assert "95% observed-information" in done.stdout and "95% percentile" in done.stdout
    row = next(line for line in done.stdout.splitlines() if "filter.w" in line and "Andrews" in line)
    assert "not applicable" in row and "at its lower bound (consistent with 0)" in row and "[0, " in row, row
    v_row = [line for line in done.stdout.splitlines() if "filter.v" in line][-1]
    assert "not applicable" not in v_row and re.search(r"\[\d[\d.]*, \d[\d.]*\].*\[\d[\d.]*, \d[\d.]*\]", v_row), v_row
    assert (tmp_path / "out" / "fit-bootstrap.png").exists()


# summary(): the bootstrap's table has the likelihood interval (the fit's method and level) beside the
# percentile interval, per setting, as the fit's own table gives it.
def test_summary_shows_the_likelihood_interval_beside_the_bootstrap(at_bound):
    text = at_bound.summary()
    lines = text.splitlines()
    head = next(i for i, line in enumerate(lines) if line.startswith("parametric bootstrap"))
    assert "90% observed-information" in lines[head + 1] and "90% percentile" in lines[head + 1]
    w, v = at_bound.parameters["filter.w"], at_bound.parameters["filter.v"]
    b = at_bound.bootstrap.parameters["filter.v"]
    w_row = next(line for line in lines[head:] if line.startswith("filter.w"))
    v_row = next(line for line in lines[head:] if line.startswith("filter.v"))
    assert f"[0, {w.ci_high:.4g}]" in w_row and "not applicable" in w_row
    assert f"[{v.ci_low:.4g}, {v.ci_high:.4g}]" in v_row and f"[{b.ci_low:.4g}, {b.ci_high:.4g}]" in v_row


# _repr_html_: the bootstrap is there, with the likelihood interval beside it and "not applicable" for w.
def test_repr_html_shows_the_bootstrap(at_bound):
    page = at_bound._repr_html_()
    assert "parametric bootstrap: 19 logs simulated from the fit and refitted, seed 3" in page
    assert "<th>90% percentile</th>" in page and "<th>90% observed-information</th>" in page
    v, b = at_bound.parameters["filter.v"], at_bound.bootstrap.parameters["filter.v"]
    assert f"<td>[{v.ci_low:.4g}, {v.ci_high:.4g}]</td><td>[{b.ci_low:.4g}, {b.ci_high:.4g}]</td>" in page
    w_row = re.search(r"<tr><td>filter\.w</td>.*?</tr>", page.split("parametric bootstrap")[1]).group(0)
    assert "not applicable" in w_row and "Andrews 2000" in w_row


# Refits all at one point (a flat direction) still make a panel: one bar, numbered ticks, the interval's lines.
def test_refits_at_one_point_make_a_panel(interior):
    from dataclasses import replace

    v = interior.bootstrap.parameters["filter.v"]
    same = replace(interior, bootstrap=replace(interior.bootstrap, parameters={
        **interior.bootstrap.parameters, "filter.v": replace(v, values=(1.7,) * len(v.values))}))
    _, v_ax = _panels(same)
    assert len(_numbers(v_ax)) >= 2
    p = interior.parameters["filter.v"]
    assert _lines(v_ax, "likelihood-interval") == pytest.approx([p.ci_low, p.ci_high], rel=1e-12)


# An entry whose upper end is lost at a search range's end that is no bound (here v's refits as they are, with
# the reason of test_bootstrap's hand-built draw past a variance's ceiling) is not applicable, never a one-sided
# bound: the panel draws no percentile line, its title says "not applicable" and the reason in short, its
# legend names no bound; summary()'s row says "not applicable" with the reason.
def test_an_entry_with_an_end_at_the_ceiling_is_shown_not_applicable(interior):
    from dataclasses import replace

    from kalcal.fitting.mle import Free
    from tests.fitting.test_bootstrap import _toy

    toy = _toy(Free("filter.v", 1.0, 1e-3, 1.0), 0.5, 0.5)
    assert not toy.applicable and toy.reason.startswith("one end at the search range's end")
    v = interior.bootstrap.parameters["filter.v"]
    lost = replace(interior, bootstrap=replace(interior.bootstrap, parameters={
        **interior.bootstrap.parameters, "filter.v": replace(v, applicable=False, ci_low=None, ci_high=None, reason=toy.reason)}))
    _, v_ax = _panels(lost)
    assert _lines(v_ax, "percentile-interval") == []
    assert v_ax.get_title().startswith("filter.v: percentile interval not applicable\none end at the search range's end")
    legend = [text.get_text() for text in v_ax.get_legend().get_texts()]
    assert not any("bound" in text or "percentile" in text for text in legend), legend
    row = next(line for line in lost.summary().splitlines()[::-1] if line.startswith("filter.v"))
    assert "not applicable" in row and "one end at the search range's end: the upper end" in row and "one-sided" not in row
