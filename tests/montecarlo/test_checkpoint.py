"""Checkpoints: a run resumed from its checkpoint equals an uninterrupted one (no Dask involved)."""

import json
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from kalcal.errors import ConfigError
from kalcal.scenarios.accel_gps.settings import AccelGpsScenario
from kalcal.models.config import apply_settings
from kalcal.montecarlo import checkpoint
from kalcal.montecarlo.engine import run_monte_carlo
from kalcal.scenarios.accel_gps.problem import accel_gps_problem
from tests._helpers import sums_equal


def _problem():
    return accel_gps_problem(apply_settings(AccelGpsScenario(), {"scenario.duration": 4.0}))


def test_checkpoint_from_other_settings_is_refused(tmp_path):
    path = tmp_path / "run.ckpt"
    run_monte_carlo(_problem(), 3000, seed=1, block_size=1000, checkpoint=path)
    assert path.exists()
    with pytest.raises(ConfigError, match="other settings"):
        run_monte_carlo(_problem(), 3000, seed=2, block_size=1000, checkpoint=path)
    path.write_bytes(b"not a checkpoint")
    with pytest.raises(ConfigError, match="not a kalcal checkpoint"):
        run_monte_carlo(_problem(), 3000, seed=1, block_size=1000, checkpoint=path)


def test_resume_skips_finished_blocks_and_gives_the_same_sums(tmp_path):
    problem = _problem()
    path = tmp_path / "run.ckpt"
    whole = run_monte_carlo(problem, 5000, seed=4, block_size=1000)
    first = run_monte_carlo(problem, 5000, seed=4, block_size=1000, checkpoint=path)
    sums, next_block = checkpoint.load(path, checkpoint.fingerprint({"n": 5000, "seed": 4, "engine": "exact", "block_size": 1000}))
    assert next_block == 5 and sums_equal(sums, whole.sums)
    # pretend the run died after two blocks: keep the fold of blocks 0 and 1 only
    partial = run_monte_carlo(problem, 2000, seed=4, block_size=1000).sums
    checkpoint.save(path, partial, 2, checkpoint.fingerprint({"n": 5000, "seed": 4, "engine": "exact", "block_size": 1000}))
    resumed = run_monte_carlo(problem, 5000, seed=4, block_size=1000, checkpoint=path)
    assert resumed.resumed_blocks == 2 and sums_equal(resumed.sums, whole.sums) and sums_equal(first.sums, whole.sums)


def test_sigkill_mid_run_then_resume_equals_uninterrupted(tmp_path):
    """Kill the CLI with SIGKILL once its checkpoint exists; the same command then finishes the run."""
    args = ["verify", "-n", "120000", "--seed", "6", "--threads", "1", "--no-report", "--long-run", "0"]
    kalcal = [sys.executable, "-m", "kalcal.cli"]
    reference = tmp_path / "reference"
    subprocess.run([*kalcal, *args, "--out", str(reference)], check=True, capture_output=True)
    ckpt = tmp_path / "run.ckpt"
    command = [*kalcal, *args, "--out", str(tmp_path / "resumed"), "--checkpoint", str(ckpt)]
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 60
    while not ckpt.exists() and time.time() < deadline and process.poll() is None:
        time.sleep(0.01)
    assert process.poll() is None, "the run finished before it could be killed; make it longer"
    process.send_signal(signal.SIGKILL)
    process.wait()
    assert not (tmp_path / "resumed" / "summary.json").exists()
    subprocess.run(command, check=True, capture_output=True)
    a = json.loads((reference / "summary.json").read_text())
    b = json.loads((tmp_path / "resumed" / "summary.json").read_text())
    assert b["timing"]["resumed_blocks"] > 0
    for key in ("tests", "final", "residual_correlation", "verdict"):
        assert a[key] == b[key], key


def test_fingerprint_sees_every_digit_of_an_array():
    a = {"w": np.array([[0.123456789012345]])}
    b = {"w": np.array([[0.123456789012346]])}
    assert checkpoint.fingerprint(a) != checkpoint.fingerprint(b)
    assert checkpoint.fingerprint(a) == checkpoint.fingerprint({"w": np.array([[0.123456789012345]])})
