"""kalcal.simulate, kalcal.sweep and ``kalcal noise --kalibr``: the calls behind the other commands."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

import kalcal
from kalcal.cli import app


def test_simulate_gives_dataframes_that_calibrate_takes_and_saves_the_cli_files(tmp_path):
    result = kalcal.simulate("accel-gps", seed=3, settings={"scenario.duration": 10})
    assert sorted(result.logs) == ["gps", "imu", "truth"] and result.truth is None
    assert list(result.logs["imu"].columns) == ["time", "accel"]
    calibration = kalcal.calibrate("accel-gps", imu=result.logs["imu"], gps=result.logs["gps"])
    assert calibration.bias_std > 0
    paths = result.save(tmp_path / "api")
    cli = tmp_path / "cli"
    assert CliRunner().invoke(app, ["simulate", "accel-gps", "--seed", "3", "--set", "scenario.duration=10",
                                    "--out", str(cli)]).exit_code == 0
    for name in ("imu.csv", "gps.csv", "truth.csv"):
        assert (tmp_path / "api" / name).read_bytes() == (cli / name).read_bytes()
    assert sorted(p.name for p in paths.values()) == ["gps.csv", "imu.csv", "truth.csv"]


def test_simulate_scale_bias_carries_its_truth(tmp_path):
    result = kalcal.simulate("scale-bias", seed=1, out=tmp_path / "sb")
    assert list(result.logs) == ["data"] and {"scale_error", "bias"} <= set(result.truth)
    written = json.loads((tmp_path / "sb" / "truth.json").read_text())
    assert written["bias"] == pytest.approx(result.truth["bias"])
    assert result.paths["truth"] == tmp_path / "sb" / "truth.json"


def test_sweep_writes_a_run_per_value(tmp_path):
    result = kalcal.sweep(
        "accel-gps", "filter.accel_noise_std", [0.01, 0.02], n=300, out=tmp_path / "sw",
        settings={"scenario.duration": 2},
    )
    assert list(result.table["filter.accel_noise_std"]) == [0.01, 0.02]
    assert (tmp_path / "sw" / "sweep.png").is_file()
    with pytest.raises(kalcal.KalcalError, match="at least two values"):
        kalcal.sweep("accel-gps", "filter.accel_noise_std", [0.01], n=300, out=tmp_path / "one")


def test_noise_kalibr_option_writes_imu_yaml(tmp_path):
    rate, n = 100.0, 2**15
    frame = pd.DataFrame({"time": np.arange(n) / rate, "accel": np.random.default_rng(0).normal(0, 0.02, n)})
    frame.to_csv(tmp_path / "static.csv", index=False)
    out = tmp_path / "noise"
    result = CliRunner().invoke(app, ["noise", "--imu", str(tmp_path / "static.csv"), "--out", str(out), "--kalibr"])
    assert result.exit_code == 0, result.output
    assert result.output.strip().splitlines()[-1] == f"wrote {out}/: summary.json, allan.csv, allan.png, filter.toml, imu.yaml"
    document = yaml.safe_load((out / "imu.yaml").read_text())
    summary = json.loads((out / "summary.json").read_text())
    # the density is N, the per-sample std times sqrt(dt)
    assert document["accelerometer_noise_density"] == pytest.approx(summary["velocity_random_walk"]["value"], rel=1e-5)
    assert document["accelerometer_noise_density"] == pytest.approx(
        summary["accel_noise_std"]["value"] * np.sqrt(1 / rate), rel=1e-5
    )
    assert document["update_rate"] == pytest.approx(rate)
