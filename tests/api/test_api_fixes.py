"""The API's results and Model compare by identity, and the review's other fixes."""

from __future__ import annotations

import kalcal


def test_results_and_models_compare_by_identity_and_hash():
    model = kalcal.Model(
        phi=[[1.0, 0.1], [0.0, 1.0]], gamma=[[0.005], [0.1]], h=[[1.0, 0.0]],
        w=[[0.04]], v=[[4.0]], x0=[0.0, 10.0], m0=[[25.0, 0.0], [0.0, 1.0]],
        steps_per_update=10, updates=30, sample_period=0.1,
    )
    twin = kalcal.Model(**model.__dict__)
    assert model == model and model != twin
    assert hash(model) != hash(twin) or model is not twin
    result = kalcal.verify(model, n=200)
    assert result == result and result != kalcal.verify(model, n=200)
    hash(result)
    sim = kalcal.simulate("accel-gps", seed=1, settings={"scenario.duration": 2})
    assert sim == sim and hash(sim) == hash(sim)
    calibration = kalcal.calibrate("accel-gps", imu=sim.logs["imu"], gps=sim.logs["gps"])
    assert calibration == calibration and hash(calibration) == hash(calibration)


def test_kalcal_gives_its_version_as_the_package_metadata_does():
    """The version is written once, in kalcal/_version.py, which pyproject.toml reads: the installed
    metadata says the same."""
    import subprocess
    import sys
    from importlib.metadata import version

    code = (
        "import kalcal; v = kalcal.__version__; from kalcal import __version__; "
        "print(v == __version__, v)"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stdout.split() == ["True", version("kalcal")], done.stdout + done.stderr


def test_dir_lists_the_exports_and_dunders_only():
    names = dir(kalcal)
    assert set(names) - set(kalcal.__all__) == {n for n in names if n.startswith("__") and n.endswith("__")} - set(kalcal.__all__)
    for helper in ("version", "sys", "types", "import_module"):
        assert helper not in names
    from kalcal.stats.results import Cause, CheckPart, CheckResult

    assert (kalcal.CheckResult, kalcal.CheckPart, kalcal.Cause) == (CheckResult, CheckPart, Cause)


def test_sweep_refuses_zero_threads_as_verify_does(tmp_path):
    import pytest

    for call in (
        lambda: kalcal.verify("accel-gps", n=300, threads=0),
        lambda: kalcal.sweep("accel-gps", "filter.accel_noise_std", [0.01, 0.02], n=300, out=tmp_path / "s", threads=0),
    ):
        with pytest.raises(kalcal.KalcalError, match="--threads: expected a positive number, got 0"):
            call()
    assert not (tmp_path / "s").exists()


def test_a_loaded_model_takes_settings_and_refusals_as_its_file_does():
    from pathlib import Path

    import pytest

    path = Path(__file__).parents[2] / "examples" / "constant_velocity.toml"
    model = kalcal.load_model(path)
    result = kalcal.verify(model, n=300, settings={"filter.w": [[0.01]]})
    assert result.scenario.filter.w.tolist() == [[0.01]]
    assert result.scenario.truth.w.tolist() == kalcal.verify(path, n=300).scenario.truth.w.tolist()
    assert result.to_dict()["final"] == kalcal.verify(path, n=300, settings={"filter.w": [[0.01]]}).to_dict()["final"]
    with pytest.raises(kalcal.KalcalError, match=r"^--long-run: not available for a model file \(.*constant_velocity.toml\)"):
        kalcal.verify(model, n=300, long_run=100)
    with pytest.raises(kalcal.KalcalError, match=r"^filter.w: expected a positive semi-definite"):
        kalcal.verify(model, n=300, settings={"filter.w": [[-1.0]]})


def _static_log(tmp_path):
    import numpy as np
    import pandas as pd

    rate, n = 100.0, 2**15
    frame = pd.DataFrame({"time": np.arange(n) / rate, "accel": np.random.default_rng(0).normal(0, 0.02, n)})
    frame.to_csv(tmp_path / "static.csv", index=False)
    return frame


def test_noise_writes_imu_yaml_by_default_and_names_it_only_when_written(tmp_path):
    import json

    import pytest
    import yaml

    frame = _static_log(tmp_path)
    result = kalcal.noise(frame, out=tmp_path / "api")
    assert result.paths["kalibr"] == str(tmp_path / "api" / "imu.yaml")
    assert (tmp_path / "api" / "imu.yaml").read_text() == result.kalibr_yaml()
    assert sorted(result.save(tmp_path / "saved")) == ["allan", "filter", "kalibr", "plot", "summary"]
    text = (tmp_path / "saved" / "imu.yaml").read_text()
    assert "Kalibr cannot load" in text.split("accelerometer_noise_density")[0]
    assert yaml.safe_load(text)["gyroscope_noise_density"] is None
    # without it, a file of that name is the user's: neither refused nor touched, and not in the manifest
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "imu.yaml").write_text("mine\n")
    paths = kalcal.noise(frame, out=tmp_path / "mine", kalibr=False).paths
    assert "kalibr" not in paths and (tmp_path / "mine" / "imu.yaml").read_text() == "mine\n"
    manifest = json.loads((tmp_path / "mine" / ".kalcal-manifest.json").read_text())
    assert "imu.yaml" not in json.dumps(manifest)
    # with it, a stray imu.yaml that no manifest lists is refused, as any other output's name
    (tmp_path / "stray").mkdir()
    (tmp_path / "stray" / "imu.yaml").write_text("mine\n")
    with pytest.raises(kalcal.KalcalError, match="imu.yaml"):
        kalcal.noise(frame, out=tmp_path / "stray")


def test_cli_noise_can_leave_imu_yaml_out(tmp_path):
    from typer.testing import CliRunner

    from kalcal.cli import app

    _static_log(tmp_path)
    out = tmp_path / "n"
    done = CliRunner().invoke(app, ["noise", "--imu", str(tmp_path / "static.csv"), "--out", str(out), "--no-kalibr"])
    assert done.exit_code == 0, done.output
    assert done.output.strip().splitlines()[-1] == f"wrote {out}/: summary.json, allan.csv, allan.png, filter.toml"
    assert not (out / "imu.yaml").exists()


def test_an_unidentified_accelerometer_value_is_null_with_its_bound():
    import numpy as np
    import yaml

    from kalcal.calibration.kalibr import kalibr_yaml
    from kalcal.calibration.noise import identify_noise

    result = identify_noise(np.random.default_rng(2).normal(0, 0.02, 2**14), 100.0)
    assert result.rate_random_walk.value is None  # white noise alone: no walk to see
    text = kalibr_yaml(result)
    line = next(line for line in text.splitlines() if line.startswith("accelerometer_random_walk"))
    assert yaml.safe_load(text)["accelerometer_random_walk"] is None and "not identified (<" in line


def test_sweep_returns_a_frozen_result_with_its_runs_summaries_and_paths(tmp_path):
    import dataclasses
    import json

    import pytest

    out = tmp_path / "sw"
    result = kalcal.sweep("accel-gps", "filter.accel_noise_std", [0.01, 0.02], n=300, out=out, settings={"scenario.duration": 2})
    assert isinstance(result, kalcal.SweepResult) and result.values == ["0.01", "0.02"]
    assert result.runs == [out / "filter.accel_noise_std=0.01", out / "filter.accel_noise_std=0.02"]
    for run, summary in zip(result.runs, result.summaries):
        assert json.loads((run / "summary.json").read_text()) == summary
    assert result.paths == {"table": out / "sweep.csv", "summary": out / "sweep.json", "figure": out / "sweep.png"}
    assert list(result.table["verdict"]) == [s["verdict"] for s in result.summaries]
    with pytest.raises(dataclasses.FrozenInstanceError):
        result.key = "other"  # type: ignore[misc]


def test_report_redraws_a_saved_verification_and_the_cli_calls_it(tmp_path, monkeypatch):
    from typer.testing import CliRunner

    import kalcal.api.report
    from kalcal.cli import app

    run = tmp_path / "run"
    kalcal.verify("accel-gps", n=300, settings={"scenario.duration": 2}, long_run=0, out=run)
    assert not (run / "report.html").exists()
    paths = kalcal.report(run, realization=1)
    assert paths == {"report": run / "report.html", "figures": run / "figures"}
    assert paths["report"].is_file() and any(paths["figures"].iterdir())
    with __import__("pytest").raises(kalcal.KalcalError, match="realization"):
        kalcal.report(run, realization=300)
    calls = []
    original = kalcal.api.report.report
    monkeypatch.setattr(kalcal.api.report, "report", lambda *a, **k: calls.append(a) or original(*a, **k))
    done = CliRunner().invoke(app, ["report", str(run)])
    assert done.exit_code == 0, done.output
    assert calls and done.output.strip().splitlines()[-1] == f"wrote {run}/: report.html, figures/"


def test_calibrate_cli_names_the_files_the_call_wrote(tmp_path, monkeypatch):
    from typer.testing import CliRunner

    from kalcal.cli import app
    from kalcal.results.calibration import CalibrationResult

    sim = tmp_path / "sim"
    kalcal.simulate("accel-gps", seed=0, settings={"scenario.duration": 10}, out=sim)
    original = CalibrationResult.with_paths

    def fewer(self, paths):
        return original(self, {k: v for k, v in paths.items() if k != "calibration.png"})

    monkeypatch.setattr(CalibrationResult, "with_paths", fewer)
    out = tmp_path / "cal"
    done = CliRunner().invoke(app, ["calibrate", "accel-gps", "--imu", str(sim / "imu.csv"), "--gps", str(sim / "gps.csv"),
                                    "--out", str(out)])
    assert done.exit_code == 0, done.output
    assert done.output.strip().splitlines()[-1] == f"wrote {out}/: estimates.csv, summary.json"


def test_sweep_requires_out_and_writes_nothing_unasked(tmp_path, monkeypatch):
    import pytest

    monkeypatch.chdir(tmp_path)
    with pytest.raises(kalcal.KalcalError, match="^out: required"):
        kalcal.sweep("accel-gps", "filter.accel_noise_std", [0.01, 0.02], n=300)
    assert list(tmp_path.iterdir()) == []
