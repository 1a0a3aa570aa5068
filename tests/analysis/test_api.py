"""``kalcal.analyze`` and ``kalcal analyze``: the result object, its files as one set, and bad input in one line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

import kalcal
from kalcal.cli import app

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
SHORT = {"scenario.duration": 6, "truth.accel_noise_std": 0.04, "filter.accel_noise_std": 0.02}


def test_analyze_returns_the_final_budget_and_dataset():
    result = kalcal.analyze("accel-gps", settings=SHORT)
    assert isinstance(result, kalcal.AnalysisResult)
    assert result.paths == {} and result.document["power"] is result.power
    assert [(row["name"], row["part"]) for row in result.power][:4] == [
        ("mean_error", None), ("covariance", None), ("covariance", "elements"), ("covariance", "centered_nees")
    ]
    assert result.sensitivity is None  # the filter is mistuned: the power table applies, not a sensitivity
    final = result.final
    assert final["time"] == 6.0 and final["units"] == ["m", "m/s", "m/s^2"]
    np.testing.assert_allclose(np.sum([b["final"] for b in result.budget], axis=0), final["error_covariance"], rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(final["error_covariance"], result.dataset["error_covariance"].values[-1])
    document = result.to_dict()
    assert list(document)[0] == "schema_version" and list(document)[-1] == "nonfinite"
    assert document["power"] == result.power and document["realizations"] == 300_000
    assert document["sensitivity"] is None
    json.dumps(document, allow_nan=False)
    assert "AnalysisResult" in repr(result) and "top source" in result._repr_html_()


def test_analyze_writes_one_set_and_save_writes_the_same(tmp_path):
    result = kalcal.analyze("accel-gps", settings=SHORT, n=50_000, out=tmp_path / "run")
    assert set(result.paths) == {"summary", "dataset", "sigma", "budget"}
    assert all(path.is_file() and path.parent.name in ("run", "figures") for path in result.paths.values())
    written = json.loads((tmp_path / "run" / "analysis.json").read_text())
    assert written["realizations"] == 50_000 and written["final"] == result.final
    manifest = json.loads((tmp_path / "run" / ".kalcal-manifest.json").read_text())
    assert manifest["command"] == "analyze"
    with xr.open_dataset(result.paths["dataset"], engine="scipy") as ds:
        assert ds["budget"].dims == ("source", "update", "state", "state_col")
    again = result.save(tmp_path / "again")
    assert json.loads(again["summary"].read_text())["budget"] == written["budget"]


def test_model_file_is_analyzed():
    result = kalcal.analyze(EXAMPLES / "constant_velocity_mistuned.toml")
    assert [b["kind"] for b in result.budget].count("process") >= 1
    assert result.final["states"] == list(result.dataset["state"].values)


def test_scale_bias_and_bad_n_are_refused_in_one_line():
    with pytest.raises(kalcal.KalcalError, match="scale-bias: no exact covariance analysis"):
        kalcal.analyze("scale-bias")
    with pytest.raises(kalcal.KalcalError, match="-n: expected a positive number"):
        kalcal.analyze("accel-gps", n=0)


def test_command_prints_the_table_and_writes_the_set(tmp_path):
    out = tmp_path / "cli"
    run = CliRunner().invoke(
        app, ["analyze", "--set", "scenario.duration=6", "--set", "truth.bias_walk_std=2e-4", "--out", str(out)], catch_exceptions=False
    )
    assert run.exit_code == 0, run.output
    assert "top source" in run.output and "measurement:velocity" in run.output and "bias (m/s^2)" in run.output
    assert (out / "analysis.json").is_file() and (out / "figures" / "budget.png").is_file()


def test_command_refuses_scale_bias_with_status_2(tmp_path):
    run = CliRunner().invoke(app, ["analyze", "scale-bias", "--out", str(tmp_path / "x")], catch_exceptions=False)
    assert run.exit_code == 2
    assert "scale-bias: no exact covariance analysis" in run.output
    assert not (tmp_path / "x").exists()


def test_a_larger_truth_names_its_sources_by_its_own_states_and_its_budget_sums_to_p_true():
    result = kalcal.analyze(str(EXAMPLES / "accel_gps_colored_gps.toml"))
    sources = [term["source"] for term in result.budget]
    assert max(result.budget, key=lambda term: term["final"][0][0])["source"] == "process:w2"  # docs/custom-models.md
    assert "prior:gps_position_error" in sources and not any(name.startswith("prior:x") for name in sources)
    total = sum(np.asarray(term["final"]) for term in result.budget)
    true = np.asarray(result.final["error_covariance"])
    np.testing.assert_allclose(total, true, rtol=1e-9, atol=1e-12 * np.abs(true).max())
    # the filter believes far less position error than the coloured GPS error gives it (docs/custom-models.md)
    ratio = true[0, 0] / np.asarray(result.final["filter_covariance"])[0, 0]
    assert round(ratio, 1) == 68.5, ratio  # docs/custom-models.md


def test_command_prints_the_power_and_for_a_correct_filter_the_sensitivity(tmp_path):
    run = CliRunner().invoke(
        app, ["analyze", str(EXAMPLES / "constant_velocity.toml"), "-n", "20000", "--out", str(tmp_path / "a")], catch_exceptions=False
    )
    assert run.exit_code == 0, run.output
    assert "power at N = 20,000: verdict" in run.output and "not detected up to N = 1,000,000,000" in run.output
    assert "detected at N = 20,000 with power 0.99 (a correct filter): w ±4.4%, v ±2.8%, m0 ±3.4%" in run.output
    written = json.loads((tmp_path / "a" / "analysis.json").read_text())
    assert [row["setting"] for row in written["sensitivity"]] == ["truth.w", "truth.v", "truth.m0"]
    assert all(set(row) == {"name", "part", "power_low", "power_high", "detectable", "detection_n"} for row in written["power"])


def test_verify_writes_and_prints_the_power_it_had(tmp_path):
    out = tmp_path / "v"
    run = CliRunner().invoke(
        app, ["verify", str(EXAMPLES / "constant_velocity_mistuned.toml"), "-n", "200", "--no-report", "--out", str(out)],
        catch_exceptions=False,
    )
    assert run.exit_code == 0, run.output
    assert "power at N = 200: verdict" in run.output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["power_reason"] is None
    rows = {(row["name"], row["part"]): row for row in summary["power"]}
    assert rows[("covariance", None)]["detectable"] and rows[("mean_error", None)]["detectable"] is False


def test_undetectable_but_not_equal_is_not_called_a_correct_filter(tmp_path):
    """A truth 1e-7 off in v is detected by no check up to N_CAP, but it is not the filter: the command says so."""
    run = CliRunner().invoke(
        app,
        ["analyze", str(EXAMPLES / "constant_velocity.toml"), "--set", "truth.v=[[4.0000004]]", "-n", "20000", "--out", str(tmp_path / "a")],
        catch_exceptions=False,
    )
    assert run.exit_code == 0, run.output
    assert "with power 0.99 (no check detects the truth up to N = 1,000,000,000):" in run.output
    assert "(a correct filter)" not in run.output and "no check can detect it" not in run.output


def test_verify_of_a_correct_filter_says_no_check_can_detect_it(tmp_path):
    out = tmp_path / "v"
    run = CliRunner().invoke(
        app, ["verify", str(EXAMPLES / "constant_velocity.toml"), "-n", "200", "--no-report", "--out", str(out)], catch_exceptions=False
    )
    assert run.exit_code == 0, run.output
    assert "(not detected up to N = 1,000,000,000: no check can detect it (the truth equals the filter))" in run.output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["power_truth_equals_filter"] is True
    result = kalcal.verify(EXAMPLES / "constant_velocity_mistuned.toml", 200)
    assert result.power == result.summary["power"] and result.summary["power_truth_equals_filter"] is False
    assert any(row["detectable"] for row in result.power)
