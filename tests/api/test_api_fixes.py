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


def test_import_kalcal_reads_the_version_only_when_asked():
    import subprocess
    import sys

    code = (
        "import sys, kalcal; print('importlib.metadata' in sys.modules); v = kalcal.__version__; "
        "from kalcal import __version__; print(v == __version__ and bool(v))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stdout.split() == ["False", "True"], done.stdout + done.stderr


def test_dir_lists_the_exports_and_dunders_only():
    names = dir(kalcal)
    assert set(names) - set(kalcal.__all__) == {n for n in names if n.startswith("__") and n.endswith("__")} - set(kalcal.__all__)
    for helper in ("version", "sys", "types", "import_module"):
        assert helper not in names
    from kalcal.verify.results import Cause, CheckPart, CheckResult

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
    assert result.run.scenario.filter.w.tolist() == [[0.01]]
    assert result.run.scenario.truth.w.tolist() == kalcal.verify(path, n=300).run.scenario.truth.w.tolist()
    assert result.to_dict()["final"] == kalcal.verify(path, n=300, settings={"filter.w": [[0.01]]}).to_dict()["final"]
    with pytest.raises(kalcal.KalcalError, match=r"^--long-run: not available for a model file \(.*constant_velocity.toml\)"):
        kalcal.verify(model, n=300, long_run=100)
    with pytest.raises(kalcal.KalcalError, match=r"^filter.w: expected a positive semi-definite"):
        kalcal.verify(model, n=300, settings={"filter.w": [[-1.0]]})
