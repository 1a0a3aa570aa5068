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
