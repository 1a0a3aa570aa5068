"""``kalcal verify MODEL.toml``: the examples pass and fail as documented, the report rebuilds, errors are one line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from kalcal.cli import app

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
EXAMPLE = EXAMPLES / "constant_velocity.toml"
MISTUNED = EXAMPLES / "constant_velocity_mistuned.toml"


def _invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)


def _verify(out, *args, n=4096):
    return _invoke("verify", *args, "-n", n, "--out", out)


def _verdicts(out) -> dict[str, bool]:
    summary = json.loads((Path(out) / "summary.json").read_text())
    return {t["name"]: t["passed"] for t in summary["tests"]}


def test_the_example_passes_and_its_report_rebuilds_without_the_file(tmp_path):
    model = tmp_path / "cv.toml"
    model.write_text(EXAMPLE.read_text())
    out = tmp_path / "run"
    result = _verify(out, model, "--strict", "--seed", "2", "--no-report")
    assert result.exit_code == 0, result.output + result.stderr
    assert "kalcal verify constant-velocity" in result.output and "verdict: PASS" in result.output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["scenario"] == "constant-velocity" and summary["verdict"] == "pass"
    assert set(summary["settings"]) == {"model", "filter", "truth"}
    assert summary["settings"]["model"]["file"] == str(model)
    assert summary["settings"]["filter"]["w"] == [[0.04]] and summary["settings"]["truth"] == summary["settings"]["filter"]
    assert summary["final"]["states"] == ["position", "velocity"] and summary["final"]["units"] == ["m", "m/s"]
    with xr.open_dataset(out / "stats.nc") as stats:
        assert stats.sizes["time"] == 30 and stats.sizes["state"] == 2 and stats.sizes["measurement"] == 1
        np.testing.assert_allclose(stats["time"].values, np.arange(1, 31), rtol=1e-12)
    # `kalcal report` (which `kalcal verify` calls unless --no-report) rebuilds the model from summary.json
    model.unlink()
    report = _invoke("report", out, "--realization", 7)
    assert report.exit_code == 0, report.output + report.stderr
    html = (out / "report.html").read_text()
    assert "kalcal verification report: constant-velocity" in html and "<code>filter.w</code>" in html
    assert (out / "figures" / "state_velocity.png").is_file() and (out / "figures" / "nis.png").is_file()


def test_the_mistuned_example_fails_the_covariance_check(tmp_path):
    result = _verify(tmp_path, MISTUNED, "--strict", "--no-report")
    assert result.exit_code == 1
    verdicts = _verdicts(tmp_path)
    assert not verdicts["covariance"] and verdicts["mean_error"]
    assert "overconfident" in result.output


def test_a_filter_retuned_with_set_fails_like_the_mistuned_file(tmp_path):
    result = _verify(tmp_path / "set", EXAMPLE, "--no-report", "--set", "filter.w=[[0.0025]]", "--set", "model.name=cv-set")
    assert result.exit_code == 0, result.output + result.stderr
    _verify(tmp_path / "file", MISTUNED, "--no-report")
    with_set = json.loads((tmp_path / "set" / "summary.json").read_text())
    with_file = json.loads((tmp_path / "file" / "summary.json").read_text())
    assert with_set["settings"]["filter"] == with_file["settings"]["filter"]
    assert with_set["settings"]["truth"] == with_file["settings"]["truth"]
    assert with_set["tests"] == with_file["tests"]  # the same model and seed: the same numbers


def _bad_shape(tmp_path):
    path = tmp_path / "my-model.toml"
    path.write_text(EXAMPLE.read_text().replace("h     = [[1.0, 0.0]]", "h = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]"))
    return path


@pytest.mark.parametrize(
    "args, message",
    [
        (lambda tmp: [_bad_shape(tmp)], "my-model.toml: h: expected 2 columns to match phi, got shape (2, 3)"),
        (lambda tmp: [tmp / "none.toml"], "none.toml: expected a readable model file, got no such file"),
        (lambda tmp: [EXAMPLE, "--set", "truth.v=[[-1.0]]"], "kalcal: error: truth.v: expected a positive semi-definite covariance, got [[-1.0]] (eigenvalue -1)"),
        (lambda tmp: [EXAMPLE, "--set", "scenario.duration=3"], "scenario.duration: expected a model file's setting (model.{name,"),
        (lambda tmp: [EXAMPLE, "--engine", "sampled"], "--engine: 'sampled' is not available for a model file"),
        (lambda tmp: [EXAMPLE, "--long-run", "60"], "--long-run: not available for a model file"),
        (lambda tmp: [EXAMPLE, "--config", EXAMPLE], "--config: expected no config file with a model file"),
    ],
    ids=["shape", "missing-file", "set-not-psd", "set-unknown", "sampled", "long-run", "config"],
)
def test_bad_input_is_one_line_and_status_2(tmp_path, args, message):
    result = _verify(tmp_path / "out", *args(tmp_path), "--no-report", n=100)
    assert result.exit_code == 2
    assert result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("kalcal: error: ") and message in lines[0], result.stderr


def test_simulate_and_calibrate_refuse_a_model_file_without_data_saying_why(tmp_path):
    # a model file reaches a log through its [data] table: without one, simulate and calibrate say so
    for command in (["simulate"], ["calibrate", "--data", str(tmp_path / "log.csv")]):
        result = _invoke(command[0], EXAMPLE, *command[1:], "--out", tmp_path / "out")
        lines = result.stderr.strip().splitlines()
        assert result.exit_code == 2 and len(lines) == 1, result.stderr
        assert f"a model file ({EXAMPLE}): it has no [data] table" in lines[0], result.stderr


def test_a_model_file_with_too_many_updates_is_refused_by_name(tmp_path):
    from typer.testing import CliRunner

    from kalcal.cli import app

    result = CliRunner().invoke(app, ["verify", str(EXAMPLE), "-n", "300", "--out", str(tmp_path), "--set", "model.updates=3000"])
    assert result.exit_code == 2
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and "model.updates: 3,000 filter updates per realization" in lines[0], result.output


ONE_STATE = """
name = "random-walk"
sample_period = 0.1
steps_per_update = 10
updates = 20
phi = [[1.0]]
gamma = [[1.0]]
w = [[0.01]]
h = [[1.0]]
v = [[1.0]]
x0 = [0.0]
m0 = [[4.0]]
"""


def test_a_one_state_filter_gets_its_report_with_the_off_diagonal_figures_skipped(tmp_path):
    model = tmp_path / "random_walk.toml"
    model.write_text(ONE_STATE)
    out = tmp_path / "out"
    result = _invoke("verify", str(model), "-n", "500", "--out", str(out))
    assert result.exit_code == 0, result.output
    drawn = {path.stem for path in (out / "figures").glob("*.png")}
    assert "variance_diagonal" in drawn and "orthogonality_diagonal" in drawn
    assert not drawn & {"variance_offdiagonal", "orthogonality_offdiagonal"}
    page = (out / "report.html").read_text()
    assert page.count("a filter of one state has no off-diagonal elements") == 2
