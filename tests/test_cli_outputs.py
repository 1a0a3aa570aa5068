"""Every command's --out folder holds that run's outputs, whole or not at all (docs/outputs.md).

A rerun into the same folder leaves no file of the earlier run, a user's own files survive, an
interrupted or failing run leaves the previous set byte-identical, and a bad --out is one line.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from kalcal.cli import app
from kalcal.io.outputs import MANIFEST, read_manifest

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "constant_velocity.toml"
SMALL = ("-n", "2000", "--set", "scenario.duration=6")


def _invoke(*args, catch=False):
    return CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=catch)


def _ok(*args):
    result = _invoke(*args)
    assert result.exit_code == 0, result.output + result.stderr
    return result


def _tree(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _inodes(folder: Path) -> dict[str, int]:
    return {p.relative_to(folder).as_posix(): p.stat().st_ino for p in folder.rglob("*") if p.is_file()}


def _files_from(earlier: dict[str, int], folder: Path) -> list[str]:
    """Files in ``folder`` that are the very files (same inode) of an earlier listing.

    A new set's files all exist (staged) before the old ones are removed, so an inode of the old set
    cannot be reused by the new one: a shared inode means the file was left from the earlier run.
    """
    old = set(earlier.values())
    return sorted(name for name, inode in _inodes(folder).items() if inode in old and name != MANIFEST)


def _one_line_error(result, *fragments):
    assert result.exit_code == 2, (result.exit_code, result.output, result.stderr)
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("kalcal: error: "), result.stderr
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])


@pytest.fixture(scope="module")
def complete_run(tmp_path_factory):
    """A complete accel-gps verification with its report and long study: seed 0."""
    out = tmp_path_factory.mktemp("complete") / "run"
    _ok("verify", *SMALL, "--long-run", "12", "--out", out)
    return out


@pytest.fixture
def previous(complete_run, tmp_path):
    """A private copy of the complete run (cp -r: the manifest comes along) and its bytes."""
    out = tmp_path / "out"
    shutil.copytree(complete_run, out)
    (out / "my notes.txt").write_text("the user's own file")
    return out, _tree(out)


def test_a_model_file_run_into_an_accel_gps_folder_leaves_none_of_its_files(previous):
    """The README's `kalcal verify examples/constant_velocity.toml` after an accel-gps run in the same folder."""
    out, before = previous
    assert {"stats_long.nc", "figures/error_bias.png", "figures/mean_error_long.png"} <= before.keys()
    first = _inodes(out)
    _ok("verify", EXAMPLE, "-n", "2000", "--out", out)
    assert _files_from(first, out) == ["my notes.txt"]
    assert not (out / "stats_long.nc").exists()
    assert not (out / "figures" / "error_bias.png").exists() and not (out / "figures" / "mean_error_long.png").exists()
    page = (out / "report.html").read_text(encoding="utf-8")
    assert "error_bias.png" not in page and "mean_error_long.png" not in page
    manifest = read_manifest(out)
    assert manifest.complete and set(manifest.files) == set(_tree(out)) - {MANIFEST, "my notes.txt"}

    # and --long-run 0 --no-report after it: no page, no figure, no long study of the model run
    second = _inodes(out)
    _ok("verify", "-n", "2000", "--set", "scenario.duration=4", "--long-run", "0", "--no-report", "--out", out)
    assert _files_from(second, out) == ["my notes.txt"]
    assert sorted(_tree(out)) == sorted([MANIFEST, "my notes.txt", "stats.nc", "summary.json"])


def test_a_run_that_fails_in_the_middle_leaves_the_previous_set_byte_identical(previous, monkeypatch):
    out, before = previous

    def broken_writer(path, document):
        raise RuntimeError("the summary writer failed")  # after stats.nc is written, before the page

    monkeypatch.setattr("kalcal.jobs.verify.write_json", broken_writer)
    result = _invoke("verify", *SMALL, "--seed", "7", "--long-run", "0", "--out", out, catch=True)
    assert isinstance(result.exception, RuntimeError) and "summary writer" in str(result.exception)
    assert _tree(out) == before
    assert not list(out.glob(".kalcal-partial-*"))


@pytest.mark.parametrize("signum, status", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_a_run_stopped_by_a_signal_says_interrupted_and_leaves_the_previous_set(previous, signum, status):
    out, before = previous
    process = subprocess.Popen(
        [sys.executable, "-m", "kalcal.cli", "verify", "-n", "3000000", "--seed", "7", "--no-report", "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 120
    while not list(out.glob(".kalcal-partial-*")) and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.5)  # into the Monte Carlo
    process.send_signal(signum)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == status, stderr
    assert stderr.splitlines() == ["kalcal: interrupted"]
    assert _tree(out) == before
    assert not list(out.glob(".kalcal-partial-*"))


def test_out_that_is_a_file_or_cannot_be_created_is_one_line(tmp_path):
    blocker = tmp_path / "a file"
    blocker.write_text("mine")
    _one_line_error(_invoke("verify", *SMALL, "--out", blocker), f"--out {blocker}: is an existing file, not a folder")
    _one_line_error(_invoke("simulate", "accel-gps", "--out", blocker), f"--out {blocker}:", "existing file")
    _one_line_error(
        _invoke("noise", "--imu", EXAMPLE, "--out", blocker / "sub"), f"--out {blocker / 'sub'}: cannot create the folder ("
    )
    assert "Errno" not in _invoke("simulate", "accel-gps", "--out", blocker / "sub").stderr
    assert blocker.read_text() == "mine"


def test_a_users_file_named_like_an_output_is_never_replaced(tmp_path):
    """`--out .` in a folder of the user's own logs: a file kalcal did not write stops the run, untouched."""
    (tmp_path / "imu.csv").write_text("time,accel\n0,1\n")
    result = _invoke("simulate", "accel-gps", "--set", "scenario.duration=2", "--out", tmp_path)
    _one_line_error(result, "imu.csv was not written by kalcal here", "choose another --out")
    assert _tree(tmp_path) == {"imu.csv": b"time,accel\n0,1\n"}


def test_simulate_and_calibrate_reruns_replace_the_whole_set_and_keep_user_files(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "README.txt").write_text("mine")
    _ok("simulate", "accel-gps", "--set", "scenario.duration=2", "--out", out)
    first = _inodes(out)
    _ok("simulate", "scale-bias", "--out", out)
    assert _files_from(first, out) == ["README.txt"]
    assert sorted(_tree(out)) == sorted([MANIFEST, "README.txt", "data.csv", "truth.json"])

    cal = tmp_path / "cal"
    sim = tmp_path / "sim"
    _ok("simulate", "accel-gps", "--set", "scenario.duration=4", "--out", sim)
    _ok("calibrate", "accel-gps", "--imu", sim / "imu.csv", "--gps", sim / "gps.csv", "--out", cal)
    assert (cal / "calibration.png").is_file()
    _ok("calibrate", "scale-bias", "--data", out / "data.csv", "--out", cal)
    assert sorted(_tree(cal)) == sorted([MANIFEST, "estimates.csv", "summary.json"])
    # calibrating a simulated log into its own folder: the input stays, the simulation's other file goes
    _ok("calibrate", "scale-bias", "--data", out / "data.csv", "--out", out)
    assert sorted(_tree(out)) == sorted([MANIFEST, "README.txt", "data.csv", "estimates.csv", "summary.json"])


def test_a_sweep_rerun_with_other_values_leaves_no_run_of_the_first(tmp_path):
    args = ("sweep", "-n", "2000", "--set", "scenario.duration=2", "--out", tmp_path)
    _ok(*args, "--set", "filter.accel_noise_std=0.01,0.02")
    assert (tmp_path / "filter.accel_noise_std=0.01" / "summary.json").is_file()
    first = _inodes(tmp_path)
    _ok(*args, "--set", "filter.accel_noise_std=0.03,0.04")
    assert _files_from(first, tmp_path) == []
    runs = sorted(p.name for p in tmp_path.iterdir() if p.is_dir())
    assert runs == ["filter.accel_noise_std=0.03", "filter.accel_noise_std=0.04"]
    assert read_manifest(tmp_path / runs[0]).command == "verify"


def test_report_redraws_into_its_own_run_consistently(previous):
    out, before = previous
    _ok("report", out, "--realization", "17")
    after = _tree(out)
    assert {k: v for k, v in after.items() if not k.startswith(("figures/", "report.html", MANIFEST))} == {
        k: v for k, v in before.items() if not k.startswith(("figures/", "report.html", MANIFEST))
    }
    assert "Realization 17 of the 2,000" in after["report.html"].decode()
    manifest = read_manifest(out)
    assert manifest.complete and manifest.command == "verify"
    assert set(manifest.files) == set(after) - {MANIFEST, "my notes.txt"}


def test_report_draws_no_long_study_the_run_did_not_make(previous):
    """A stats_long.nc that is not the run's (the summary has no long study) is not drawn into its page."""
    out, _ = previous
    summary = json.loads((out / "summary.json").read_text())
    summary["long_run"] = None
    (out / "summary.json").write_text(json.dumps(summary))
    _ok("report", out)
    assert not (out / "figures" / "mean_error_long.png").exists()
    assert "is not shown" in (out / "report.html").read_text(encoding="utf-8")


def test_report_refuses_an_incomplete_folder_and_statistics_of_another_run(previous, tmp_path):
    out, _ = previous
    manifest = json.loads((out / MANIFEST).read_text())
    (out / MANIFEST).write_text(json.dumps({**manifest, "complete": False}))
    _one_line_error(_invoke("report", out), str(out), "incomplete", "run it again")
    (out / MANIFEST).write_text(json.dumps(manifest))

    other = tmp_path / "other"
    _ok("verify", *SMALL, "--seed", "5", "--long-run", "0", "--no-report", "--out", other)
    shutil.copy2(other / "stats.nc", out / "stats.nc")
    _one_line_error(_invoke("report", out), "stats.nc: from another run (seed 5", "says 0")


def test_the_command_lines_files_are_never_removed(tmp_path):
    """`kalcal calibrate --config noise/filter.toml --out noise`: the config written by `kalcal noise` stays."""
    rng = np.random.default_rng(3)
    pd.DataFrame({"time": np.arange(20_000) / 200.0, "accel": 0.02 * rng.standard_normal(20_000)}).to_csv(
        tmp_path / "static.csv", index=False
    )
    noise, sim = tmp_path / "noise", tmp_path / "sim"
    _ok("noise", "--imu", tmp_path / "static.csv", "--out", noise)
    _ok("simulate", "accel-gps", "--set", "scenario.duration=4", "--out", sim)
    config = (noise / "filter.toml").read_bytes()
    done = subprocess.run(
        [sys.executable, "-m", "kalcal.cli", "calibrate", "accel-gps", "--imu", str(sim / "imu.csv"),
         "--gps", str(sim / "gps.csv"), "--config", str(noise / "filter.toml"), "--out", str(noise)],
        capture_output=True, text=True, env={**os.environ, "COLUMNS": "200"},
    )
    assert done.returncode == 0, done.stderr
    assert sorted(_tree(noise)) == sorted([MANIFEST, "calibration.png", "estimates.csv", "filter.toml", "summary.json"])
    assert (noise / "filter.toml").read_bytes() == config
    assert "fixes_used" in json.loads((noise / "summary.json").read_text())


def test_a_checkpoint_in_the_folder_is_never_part_of_a_set(tmp_path):
    out = tmp_path / "out"
    checkpoint = out / "run.ckpt"
    args = ("verify", "-n", "5000", "--set", "scenario.duration=2", "--long-run", "0", "--no-report", "--out", out)
    _ok(*args, "--checkpoint", checkpoint)
    saved = checkpoint.read_bytes()
    assert "run.ckpt" not in read_manifest(out).files
    _ok(*args, "--checkpoint", checkpoint)  # resumes from it
    _ok(*args, "--seed", "4")  # another run into the folder, without the checkpoint
    assert checkpoint.read_bytes() == saved
    assert sorted(_tree(out)) == sorted([MANIFEST, "run.ckpt", "stats.nc", "summary.json"])


def test_the_jobs_return_the_final_paths(tmp_path):
    """The Python jobs write through the same staging: what they return is where the files now are."""
    from kalcal.jobs.simulate import simulate_accel_gps
    from kalcal.jobs.verify import verify
    from kalcal.models.registry import build_scenario

    scenario = build_scenario("accel-gps", None, ["scenario.duration=2"])
    outcome = verify(scenario, 200, 0, tmp_path / "v", long_run=0)
    assert set(outcome.paths) == {"stats", "summary"}
    assert all(path.parent == tmp_path / "v" and path.is_file() for path in outcome.paths.values())
    paths = simulate_accel_gps(scenario, 0, tmp_path / "s")
    assert paths == {name: tmp_path / "s" / f"{name}.csv" for name in ("imu", "gps", "truth")}
    assert all(path.is_file() for path in paths.values())


def test_an_interrupted_redraw_leaves_the_old_page_and_figures(previous, monkeypatch):
    out, before = previous

    def half_drawn(dataset, data, figure_dir, *args, **kwargs):
        figure_dir.mkdir(parents=True, exist_ok=True)
        (figure_dir / "state_position.png").write_bytes(b"half a figure")
        raise KeyboardInterrupt

    monkeypatch.setattr("kalcal.jobs.report.render_figures", half_drawn)
    result = _invoke("report", out, "--realization", "3", catch=True)
    assert result.exit_code != 0
    assert _tree(out) == before
    assert not list(out.glob(".kalcal-partial-*"))
