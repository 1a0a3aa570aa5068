"""Implausible logs at the command line: one-line errors (exit 2) naming the likely unit, warnings on
stderr and in summary.json, and ``--strict`` (exit 1 for calibrate; a refusal for noise)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

import kalcal
from kalcal.cli import app


def _invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim")
    assert _invoke("simulate", "accel-gps", "--seed", "3", "--out", out).exit_code == 0
    assert _invoke("simulate", "scale-bias", "--seed", "3", "--out", out / "sb").exit_code == 0
    return out


def _calibrate(sim, tmp_path, imu=None, gps=None, *extra):
    paths = {}
    for name, frame in (("imu", imu), ("gps", gps)):
        if frame is None:
            paths[name] = sim / f"{name}.csv"
        else:
            paths[name] = tmp_path / f"{name}.csv"
            frame.to_csv(paths[name], index=False)
    return _invoke(
        "calibrate", "accel-gps", "--imu", paths["imu"], "--gps", paths["gps"], "--out", tmp_path / "cal", *extra
    )


def _one_line_error(result, *fragments):
    assert result.exit_code == 2, result.output + result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("kalcal: error: "), result.stderr  # no raw library warning
    for fragment in fragments:
        assert fragment in lines[0], lines[0]


def test_times_in_milliseconds_are_exit_status_2(sim, tmp_path):
    imu, gps = pd.read_csv(sim / "imu.csv"), pd.read_csv(sim / "gps.csv")
    imu["time"] *= 1000
    gps["time"] *= 1000
    result = _calibrate(sim, tmp_path, imu, gps)
    _one_line_error(result, "accelerometer sample rate 0.2 Hz", "implausible", "are the times in milliseconds?")
    assert not (tmp_path / "cal" / "summary.json").exists()


def test_velocity_in_kmh_is_exit_status_2(sim, tmp_path):
    gps = pd.read_csv(sim / "gps.csv")
    gps["velocity"] *= 3.6
    _one_line_error(_calibrate(sim, tmp_path, None, gps), "column 'velocity'", "is the velocity in km/h instead of m/s?")


def test_acceleration_in_g_is_exit_status_2(sim, tmp_path):
    imu = pd.read_csv(sim / "imu.csv")
    imu["accel"] /= 9.80665
    _one_line_error(_calibrate(sim, tmp_path, imu), "column 'accel'", "is the acceleration in g instead of m/s^2?")


@pytest.mark.parametrize(("factor", "unit"), [(1000.0, "millimetres"), (1 / 0.3048, "feet")])
def test_position_in_mm_or_ft_is_exit_status_2(sim, tmp_path, factor, unit):
    gps = pd.read_csv(sim / "gps.csv")
    gps["position"] *= factor
    _one_line_error(_calibrate(sim, tmp_path, None, gps), "column 'position'", f"is the position in {unit} instead of m?")


def test_a_gps_log_wholly_in_feet_is_exit_status_2(sim, tmp_path):
    """Position and velocity (and their stds) in feet: consistent with each other, 3.281 times the
    accelerometer; silent on 2114039's fix (a bias of -17.9 m/s^2)."""
    gps = pd.read_csv(sim / "gps.csv")
    for column in [c for c in gps.columns if c != "time"]:
        gps[column] *= 1 / 0.3048
    _one_line_error(
        _calibrate(sim, tmp_path, None, gps), "gps.csv: ", "are its position and velocity in feet (and ft/s) instead of m"
    )


def test_gravity_left_in_is_a_warning_and_strict_exits_1(sim, tmp_path):
    """On 2114039: bias 9.848, diagnostics consistent, no warning, exit 0 with --strict."""
    imu = pd.read_csv(sim / "imu.csv")
    imu["accel"] += 9.80665
    for strict, status in (((), 0), (("--strict",), 1)):
        result = _calibrate(sim, tmp_path, imu, None, *strict)
        assert result.exit_code == status, result.output + result.stderr
        summary = json.loads((tmp_path / "cal" / "summary.json").read_text())
        assert [w["code"] for w in summary["warnings"]] == ["gravity-in-accel"]
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("kalcal: warning: "), lines
        assert "near +g (9.80665 m/s^2): was gravity removed from the vertical accelerometer?" in lines[0]


def test_one_huge_sample_is_exit_status_2_naming_the_row(sim, tmp_path):
    imu = pd.read_csv(sim / "imu.csv")
    imu.loc[1000, "accel"] = 1e300
    _one_line_error(_calibrate(sim, tmp_path, imu), "row 1001, column 'accel'", "beyond the physical limit")


def test_mapped_columns_are_named_in_the_errors(sim, tmp_path):
    imu = pd.read_csv(sim / "imu.csv").rename(columns={"time": "t", "accel": "ax"})
    imu.loc[5, "ax"] = 1e300
    result = _calibrate(sim, tmp_path, imu, None, "--imu-columns", "time=t,accel=ax")
    _one_line_error(result, "row 6, column 'ax'")


def test_genuine_log_has_an_empty_warnings_list_and_passes_strict(sim, tmp_path):
    result = _calibrate(sim, tmp_path, None, None, "--strict")
    assert result.exit_code == 0, result.output + result.stderr
    summary = json.loads((tmp_path / "cal" / "summary.json").read_text())
    assert summary["warnings"] == [] and summary["diagnostics"]["consistent"]
    assert summary["fixes_default_std"] == {"position_std": 0, "velocity_std": 0}
    assert "warning" not in result.stderr


def test_nan_per_fix_std_is_a_warning_and_strict_exits_1(sim, tmp_path):
    gps = pd.read_csv(sim / "gps.csv")
    gps["position_std"], gps["velocity_std"] = 1.0, 0.04
    gps.loc[[3, 7], "velocity_std"] = np.nan
    for strict, status in (((), 0), (("--strict",), 1)):
        result = _calibrate(sim, tmp_path, None, gps, *strict)
        assert result.exit_code == status, result.output + result.stderr
        summary = json.loads((tmp_path / "cal" / "summary.json").read_text())
        assert summary["fixes_default_std"] == {"position_std": 0, "velocity_std": 2}
        assert [w["code"] for w in summary["warnings"]] == ["default-fix-std"]
        assert "column 'velocity_std': 2 fix(es) used have no value (NaN)" in summary["warnings"][0]["message"]
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("kalcal: warning: ") and "velocity_std" in lines[0]


def test_strict_exits_1_when_the_diagnostics_say_inconsistent(sim, tmp_path):
    result = _calibrate(sim, tmp_path, None, None, "--set", "filter.gps_position_std=0.05")
    assert result.exit_code == 0, result.output + result.stderr
    summary = json.loads((tmp_path / "cal" / "summary.json").read_text())
    assert not summary["diagnostics"]["consistent"]
    assert _calibrate(sim, tmp_path, None, None, "--set", "filter.gps_position_std=0.05", "--strict").exit_code == 1


def test_noise_on_a_moving_log_warns_and_strict_refuses(sim, tmp_path):
    result = _invoke("noise", "--imu", sim / "imu.csv", "--out", tmp_path / "n")
    assert result.exit_code == 0, result.output + result.stderr
    summary = json.loads((tmp_path / "n" / "summary.json").read_text())
    assert summary["warnings"] and {w["code"] for w in summary["warnings"]} == {"not-static"}
    assert "kalcal: warning: " in result.stderr and "does not look static" in result.stderr
    assert (tmp_path / "n" / "filter.toml").read_text().startswith("# WARNING: ")
    refused = _invoke("noise", "--imu", sim / "imu.csv", "--out", tmp_path / "s", "--strict")
    _one_line_error(refused, "does not look static", "--strict")
    assert not (tmp_path / "s" / "filter.toml").exists()


def test_noise_refuses_times_in_milliseconds(tmp_path):
    rng = np.random.default_rng(2)
    frame = pd.DataFrame({"time": np.arange(4096) * 5.0, "accel": 9.81 + 0.02 * rng.standard_normal(4096)})
    frame.to_csv(tmp_path / "static.csv", index=False)
    result = _invoke("noise", "--imu", tmp_path / "static.csv", "--out", tmp_path / "n")
    _one_line_error(result, "accelerometer sample rate 0.2 Hz", "milliseconds")


def test_scale_bias_constant_sensor_is_flagged_unobservable(sim, tmp_path):
    data = pd.read_csv(sim / "sb" / "data.csv")
    good = _invoke(
        "calibrate", "scale-bias", "--data", sim / "sb" / "data.csv", "--out", tmp_path / "g", "--strict", "--prior", "settings"
    )
    assert good.exit_code == 0, good.output + good.stderr
    summary = json.loads((tmp_path / "g" / "summary.json").read_text())
    assert summary["warnings"] == [] and summary["observability"]["unobservable"] == [] and summary["consistent"]
    data["sensor"] = 1.0
    data.to_csv(tmp_path / "constant.csv", index=False)
    for strict, status in (((), 0), (("--strict",), 1)):
        result = _invoke(
            "calibrate", "scale-bias", "--data", tmp_path / "constant.csv", "--out", tmp_path / "c", "--prior", "settings", *strict
        )
        assert result.exit_code == status, result.output + result.stderr
        assert "kalcal: warning: " in result.stderr and "unobservable (no excitation)" in result.stderr
    summary = json.loads((tmp_path / "c" / "summary.json").read_text())
    assert "theta1" in summary["observability"]["unobservable"]
    assert summary["observability"]["std_ratio"]["theta1"] > 0.9
    # a constant sensor cannot follow the varying reference: its NIS is inconsistent too, so its sigma is
    # not trusted
    assert [w["code"] for w in summary["warnings"]] == ["unobservable", "noise-inconsistent", "sigma-untrusted"]
    # untrusted for the unobservable theta, with its cause and no noise advice (no fit to run)
    untrusted = summary["warnings"][2]["message"]
    assert "theta1" in untrusted and "unobservable" in untrusted and "kalcal fit" not in untrusted
    assert not summary["consistent"] and summary["mean_nis"] > summary["nis_bounds"][1]


@pytest.mark.parametrize("extra", [(), ("--set", "filter.gps_position_std=0.05")], ids=["consistent", "inconsistent"])
def test_summary_diagnostics_hold_the_pvalue_and_each_parts_bounds(sim, tmp_path, extra):
    """summary.json's diagnostics: consistent == (pvalue >= 1 - confidence), the p-value is the parts'
    Bonferroni combination, and each part (NIS, Ljung-Box) carries its statistic, bounds, share and verdict."""
    assert _calibrate(sim, tmp_path, None, None, *extra).exit_code == 0
    diagnostics = json.loads((tmp_path / "cal" / "summary.json").read_text())["diagnostics"]
    confidence, pvalue = diagnostics["confidence"], diagnostics["pvalue"]
    assert confidence == 0.99 and 0.0 <= pvalue <= 1.0
    assert diagnostics["consistent"] == (pvalue >= 1 - confidence)
    assert diagnostics["consistent"] == (extra == ())
    nis, ljung_box = diagnostics["parts"]
    assert (nis["name"], ljung_box["name"]) == ("nis", "ljung_box")
    for part in (nis, ljung_box):
        assert set(part) == {"name", "statistic", "pvalue", "lower", "upper", "confidence", "alpha", "comparisons", "passed"}
        assert part["alpha"] == pytest.approx((1 - confidence) / 2) and part["passed"] == (part["pvalue"] >= part["alpha"])
    assert pvalue == pytest.approx(min(1.0, 2 * min(nis["pvalue"], ljung_box["pvalue"])))
    assert (nis["lower"], nis["upper"]) == (diagnostics["nis_lower"], diagnostics["nis_upper"])
    assert nis["statistic"] == diagnostics["mean_nis"] and nis["lower"] < nis["upper"]
    assert ljung_box["lower"] is None and ljung_box["upper"] == diagnostics["ljung_box_upper"]
    assert ljung_box["statistic"] == max(diagnostics["ljung_box_statistic"])
    assert ljung_box["comparisons"] == len(diagnostics["ljung_box_pvalue"]) == 2


def test_scale_bias_cell_beyond_the_limit_is_exit_status_2(sim, tmp_path):
    data = pd.read_csv(sim / "sb" / "data.csv")
    data.loc[41, "sensor"] = 1e300
    data.to_csv(tmp_path / "huge.csv", index=False)
    result = _invoke("calibrate", "scale-bias", "--data", tmp_path / "huge.csv", "--out", tmp_path / "h", "--strict")
    _one_line_error(result, "row 42, column 'sensor'", "beyond the physical limit of 1e+12")
    assert not (tmp_path / "h" / "summary.json").exists()


def test_scale_bias_strict_exits_1_when_the_nis_is_inconsistent(sim, tmp_path):
    args = ("calibrate", "scale-bias", "--data", sim / "sb" / "data.csv", "--set", "filter.reference_noise_std=0.02")
    for strict, status in (((), 0), (("--strict",), 1)):
        result = _invoke(*args, "--out", tmp_path / "n", *strict)
        assert result.exit_code == status, result.output + result.stderr
        summary = json.loads((tmp_path / "n" / "summary.json").read_text())
        assert not summary["consistent"] and summary["mean_nis"] > 50
        assert [w["code"] for w in summary["warnings"]] == ["noise-inconsistent", "sigma-untrusted"]
        assert "kalcal: warning: " in result.stderr and "mean NIS" in result.stderr


def _run(*args):
    """The CLI as a user runs it, a process of its own: what reaches stderr is what the user sees (in
    process, pytest would record a raw library warning instead of printing it)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(Path(kalcal.__file__).parents[1]), env.get("PYTHONPATH", "")])
    return subprocess.run(
        [sys.executable, "-m", "kalcal.cli", *map(str, args)], capture_output=True, text=True, env=env, timeout=300
    )


def _only_kalcal_lines(process, kind):
    lines = process.stderr.strip().splitlines()
    assert lines and all(line.startswith(f"kalcal: {kind}: ") for line in lines), process.stderr


def test_a_process_prints_no_raw_library_warning(sim, tmp_path):
    imu = pd.read_csv(sim / "imu.csv")
    imu.loc[1000, "accel"] = 1e300
    imu.to_csv(tmp_path / "imu.csv", index=False)
    refused = _run("calibrate", "accel-gps", "--imu", tmp_path / "imu.csv", "--gps", sim / "gps.csv", "--out", tmp_path / "a")
    assert refused.returncode == 2, refused.stderr
    _only_kalcal_lines(refused, "error")
    data = pd.read_csv(sim / "sb" / "data.csv")
    data.loc[41, "sensor"] = 1e300  # before the limit check: exit 0 and numpy overflow warnings
    data.to_csv(tmp_path / "huge.csv", index=False)
    refused = _run("calibrate", "scale-bias", "--data", tmp_path / "huge.csv", "--out", tmp_path / "b", "--strict")
    assert refused.returncode == 2, refused.stderr
    _only_kalcal_lines(refused, "error")
    flagged = _run("noise", "--imu", sim / "imu.csv", "--out", tmp_path / "n")
    assert flagged.returncode == 0, flagged.stderr
    _only_kalcal_lines(flagged, "warning")


def test_noise_names_the_row_then_the_column_of_a_huge_sample(tmp_path):
    rng = np.random.default_rng(2)
    frame = pd.DataFrame({"time": np.arange(4096) / 200.0, "accel": 9.81 + 0.02 * rng.standard_normal(4096)})
    frame.loc[100, "accel"] = 1e300
    frame.to_csv(tmp_path / "static.csv", index=False)
    result = _invoke("noise", "--imu", tmp_path / "static.csv", "--out", tmp_path / "n")
    _one_line_error(result, "static.csv: row 101, column 'accel': 1e+300 m/s^2 is beyond the physical limit")


def test_accel_gps_scale_without_acceleration_is_unobservable_and_strict_exits_1(sim, tmp_path):
    """A constant-speed log with a scale state: an ``unobservable`` warning naming the scale and its cause,
    the scale's sigma marked untrusted and the bias's not for it, summary.json's observability shaped as
    scale-bias's; ``--strict`` exits 1. The genuine log with a scale state warns of nothing."""
    good = _calibrate(sim, tmp_path, None, None, "--set", "filter.scale_std=0.01", "--strict")
    assert good.exit_code == 0, good.output + good.stderr
    summary = json.loads((tmp_path / "cal" / "summary.json").read_text())
    assert summary["warnings"] == [] and summary["observability"]["unobservable"] == [] and summary["observability"]["cause"] is None
    imu, gps = pd.read_csv(sim / "imu.csv"), pd.read_csv(sim / "gps.csv")
    rng = np.random.default_rng(5)
    imu["accel"] = 0.05 + 0.02 * rng.standard_normal(len(imu))
    gps["position"] = 20.0 * gps["time"] + rng.standard_normal(len(gps))
    gps["velocity"] = 20.0 + 0.04 * rng.standard_normal(len(gps))
    for strict, status in (((), 0), (("--strict",), 1)):
        result = _calibrate(sim, tmp_path, imu, gps, "--set", "filter.scale_std=0.01", *strict)
        assert result.exit_code == status, result.output + result.stderr
        assert "kalcal: warning: " in result.stderr and "scale unobservable" in result.stderr
    summary = json.loads((tmp_path / "cal" / "summary.json").read_text())
    observability = summary["observability"]
    assert observability["unobservable"] == ["scale"] and observability["std_ratio"]["scale"] > 0.9
    assert set(observability["data_only"]) >= {"rcond", "singular", "std", "no_data_std", "weaker_than_prior"}
    assert "no excitation" in observability["cause"]
    codes = [w["code"] for w in summary["warnings"]]
    assert codes[0] == "unobservable" and summary["scale_sigma_trusted"] is False
    # the scale named alone: a whole sentence (it read "...; the scale an accelerometer that varies ...")
    assert summary["warnings"][0]["message"].endswith("the scale needs an accelerometer that varies well beyond its noise")
    # the scale alone unobservable leaves the bias determined: its sigma is not untrusted for the scale (it
    # was, "scale unobservable ... rests on the prior"); only the diagnostics or the windows could untrust it
    assert not summary["observability"]["data_only"]["singular"]
    assert summary["sigma_trusted"] == (summary["diagnostics"]["consistent"] and summary["stability"].get("stable") is not False)
    for warning in summary["warnings"]:
        assert warning["code"] != "sigma-untrusted" or "scale unobservable" not in warning["message"]
    # the scale's sigma is marked wherever it is shown: the table's scale row, the figure's note, the repr
    # (it was printed unmarked, "scale 0.000100755 ± 0.01", with only summary.json saying so)
    scale_row = next(line for line in result.output.splitlines() if line.lstrip("│┃ ").startswith("scale"))
    assert "NOT trusted" in scale_row, result.output
    from kalcal.scenarios.accel_gps.calibrate import sigma_note

    assert "scale" in sigma_note(summary) and "NOT trusted" in sigma_note(summary)
    api = kalcal.calibrate("accel-gps", imu=tmp_path / "imu.csv", gps=tmp_path / "gps.csv",
                           settings={"filter.scale_std": 0.01}, settings_sigma=False)
    assert api.scale_sigma_trusted is False and "scale=" in repr(api)
    assert repr(api).split("scale=")[1].split(",")[0].endswith("(sigma NOT trusted)"), repr(api)


def test_a_tight_prior_that_the_log_contradicts_is_named_as_the_cause_not_the_noise_settings(sim, tmp_path):
    """The seed-3 log with filter.bias_std = 0.0002: prior-dominates and prior-conflict (81 sigma), and the
    diagnostics inconsistent. The sigma-untrusted warning gave the diagnostics' noise advice ("the noise
    settings are too small") and a fit that keeps the same prior (which inflates the noise to absorb it):
    it names the prior as the likely cause, the bare numbers, and a looser or unset prior as the next step."""
    result = _calibrate(sim, tmp_path, None, None, "--set", "filter.bias_std=0.0002", "--no-settings-sigma", "--strict")
    assert result.exit_code == 1, result.output + result.stderr  # --strict: a prior tighter than the log warns
    summary = json.loads((tmp_path / "cal" / "summary.json").read_text())
    found = {w["code"]: w["message"] for w in summary["warnings"]}
    assert {"prior-dominates", "prior-conflict", "sigma-untrusted"} <= set(found), found
    untrusted = found["sigma-untrusted"]
    assert "the likely cause is the prior (filter.bias_std = 0.0002)" in untrusted
    assert "noise settings are too small" not in untrusted and "kalcal fit" not in untrusted
    assert "mean NIS" in untrusted and "looser filter.bias_std or leave it unset" in untrusted
    assert "noise settings are too small" not in summary["sigma_untrusted_because"]
