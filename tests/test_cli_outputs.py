"""Every command's --out folder holds that run's outputs, whole or not at all (docs/outputs.md).

A rerun into the same folder leaves no file of the earlier run, a user's own files survive, an
interrupted or failing run leaves the previous set byte-identical, and a bad --out is one line.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from kalcal.cli import app
from kalcal.io.manifest import MANIFEST, read_manifest
from tests._helpers import tree as _tree

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "constant_velocity.toml"
SMALL = ("-n", "2000", "--set", "scenario.duration=6")


def _invoke(*args, catch=False):
    return CliRunner().invoke(app, [str(a) for a in args], catch_exceptions=catch)


def _ok(*args):
    result = _invoke(*args)
    assert result.exit_code == 0, result.output + result.stderr
    return result


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

    monkeypatch.setattr("kalcal.api.verification.write_json", broken_writer)
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
    _ok("simulate", "accel-gps", "--set", "scenario.duration=3", "--seed", "4", "--out", out)
    assert _files_from(first, out) == ["README.txt"]
    assert sorted(_tree(out)) == sorted([MANIFEST, "README.txt", "gps.csv", "imu.csv", "truth.csv"])

    cal = tmp_path / "cal"
    _ok("calibrate", "accel-gps", "--imu", out / "imu.csv", "--gps", out / "gps.csv", "--out", cal)
    assert (cal / "calibration.png").is_file()
    first = _inodes(cal)
    # the README's scale-bias calibration into a folder of its own, twice: the second replaces the first
    sb, sb_cal = tmp_path / "sb", tmp_path / "sb-cal"
    _ok("simulate", "scale-bias", "--out", sb)
    _ok("calibrate", "scale-bias", "--data", sb / "data.csv", "--out", sb_cal)
    first = _inodes(sb_cal)
    _ok("calibrate", "scale-bias", "--data", sb / "data.csv", "--set", "filter.bias_std=0.2", "--out", sb_cal)
    assert _files_from(first, sb_cal) == []
    assert sorted(_tree(sb_cal)) == sorted([MANIFEST, "correction.json", "estimates.csv", "summary.json"])


def test_another_commands_folder_is_refused_and_left_whole(tmp_path):
    """`kalcal calibrate ... --out sim` into the simulation's folder would remove its truth.csv: refused."""
    sim = tmp_path / "sim"
    _ok("simulate", "accel-gps", "--set", "scenario.duration=2", "--out", sim)
    before = _tree(sim)
    result = _invoke("calibrate", "accel-gps", "--imu", sim / "imu.csv", "--gps", sim / "gps.csv", "--out", sim)
    _one_line_error(result, f"--out {sim}: holds the outputs of `kalcal simulate accel-gps`; choose another folder")
    _one_line_error(_invoke("simulate", "scale-bias", "--out", sim), "holds the outputs of `kalcal simulate accel-gps`")
    assert _tree(sim) == before


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


def test_a_run_folder_of_a_sweep_is_refused_as_part_of_the_sweeps_set(tmp_path):
    """A verify into one of a sweep's run folders would leave sweep.csv describing a run that is gone."""
    _ok("sweep", "-n", "200", "--set", "scenario.duration=2", "--set", "filter.accel_noise_std=0.01,0.02", "--out", tmp_path)
    run = tmp_path / "filter.accel_noise_std=0.01"
    before = _tree(tmp_path)
    result = _invoke("verify", "-n", "200", "--long-run", "0", "--no-report", "--set", "scenario.duration=2", "--out", run)
    _one_line_error(result, "is part of the outputs of `kalcal sweep`", str(tmp_path))
    assert _tree(tmp_path) == before


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
    """A log named on the command line that the folder's own previous run listed (a calibration's
    estimates.csv fed back as its IMU log) is kept and stays the folder's."""
    sim, cal = tmp_path / "sim", tmp_path / "cal"
    _ok("simulate", "accel-gps", "--set", "scenario.duration=2", "--out", sim)
    _ok("calibrate", "accel-gps", "--imu", sim / "imu.csv", "--gps", sim / "gps.csv", "--out", cal)
    shutil.copy2(sim / "imu.csv", cal / "imu-copy.csv")
    manifest = json.loads((cal / MANIFEST).read_text())
    (cal / MANIFEST).write_text(json.dumps({**manifest, "files": [*manifest["files"], "imu-copy.csv"]}))
    log = (cal / "imu-copy.csv").read_bytes()
    done = subprocess.run(
        [sys.executable, "-m", "kalcal.cli", "calibrate", "accel-gps", "--imu", str(cal / "imu-copy.csv"),
         "--gps", str(sim / "gps.csv"), "--out", str(cal)],
        capture_output=True, text=True, env={**os.environ, "COLUMNS": "200"},
    )
    assert done.returncode == 0, done.stderr
    assert (cal / "imu-copy.csv").read_bytes() == log
    assert "imu-copy.csv" in read_manifest(cal).files


def test_a_python_job_keeps_the_config_its_scenario_was_read_from(tmp_path):
    """No command line names the config here: the scenario carries it (docs/outputs.md)."""
    import kalcal
    from kalcal.scenarios import build_scenario

    out = tmp_path / "sim"
    kalcal.simulate(build_scenario("accel-gps", None, ["scenario.duration=2"]), 0, out=out)
    config = out / "settings.toml"
    config.write_text("[scenario]\nduration = 3\n")
    manifest = json.loads((out / MANIFEST).read_text())  # the config is a file of the folder's set
    (out / MANIFEST).write_text(json.dumps({**manifest, "files": [*manifest["files"], "settings.toml"]}))
    kalcal.simulate(build_scenario("accel-gps", config), 1, out=out)
    assert config.read_text() == "[scenario]\nduration = 3\n"
    assert sorted(_tree(out)) == sorted([MANIFEST, "gps.csv", "imu.csv", "settings.toml", "truth.csv"])


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
    import kalcal
    from kalcal.api.verification import verify
    from kalcal.scenarios import build_scenario

    scenario = build_scenario("accel-gps", None, ["scenario.duration=2"])
    outcome = verify(scenario, 200, 0, tmp_path / "v", long_run=0)
    assert set(outcome.paths) == {"stats", "summary"}
    assert all(path.parent == tmp_path / "v" and path.is_file() for path in outcome.paths.values())
    paths = kalcal.simulate(scenario, 0, out=tmp_path / "s").paths
    assert paths == {name: tmp_path / "s" / f"{name}.csv" for name in ("imu", "gps", "truth")}
    assert all(path.is_file() for path in paths.values())


def test_an_interrupted_redraw_leaves_the_old_page_and_figures(previous, monkeypatch):
    out, before = previous

    def half_drawn(dataset, data, figure_dir, *args, **kwargs):
        figure_dir.mkdir(parents=True, exist_ok=True)
        (figure_dir / "state_position.png").write_bytes(b"half a figure")
        raise KeyboardInterrupt

    monkeypatch.setattr("kalcal.reporting.figures.render_figures", half_drawn)
    result = _invoke("report", out, "--realization", "3", catch=True)
    assert result.exit_code != 0
    assert _tree(out) == before
    assert not list(out.glob(".kalcal-partial-*"))


def test_ctrl_c_with_workers_is_one_line(tmp_path):
    """Ctrl-C signals the whole process group, the Dask worker processes too: still one line on stderr
    for it. The interrupt is sent once the Monte Carlo runs on the worker, which the run's estimate note
    says (10^8 realizations: minutes on one worker, so the note always comes); a Ctrl-C while the local
    cluster starts is not taken (docs/scale-out.md)."""
    import threading

    out = tmp_path / "out"
    busy = socket.socket()  # Dask's default HTTP port taken, as by another run at the same time
    with contextlib.suppress(OSError):
        busy.bind(("0.0.0.0", 8787))
        busy.listen()
    args = ["verify", "-n", "100000000", "--workers", "1", "--no-report", "--long-run", "0", "--out", str(out)]
    process = subprocess.Popen(
        [sys.executable, "-m", "kalcal.cli", *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
    )  # fmt: skip
    lines: list[str] = []
    running = threading.Event()

    def read():
        for line in process.stderr:
            lines.append(line.rstrip("\n"))
            if "estimated wall time" in line:
                running.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        assert running.wait(120), lines
        time.sleep(0.5)  # the Monte Carlo under way, not the instant the note is written
        os.killpg(process.pid, signal.SIGINT)
        process.wait(timeout=60)
        reader.join(10)
    finally:
        busy.close()
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
    assert process.returncode == 130, lines
    assert len(lines) == 2 and lines[0].startswith("kalcal: note: estimated wall time") and lines[1] == "kalcal: interrupted", lines
    assert not out.exists()


def test_a_file_where_kalcal_writes_a_folder_is_refused_before_the_run(tmp_path, monkeypatch):
    out = tmp_path / "out"
    out.mkdir()
    (out / "figures").write_text("mine")

    def no_monte_carlo(*args, **kwargs):
        raise AssertionError("the Monte Carlo ran")

    monkeypatch.setattr("kalcal.api.verification.run_monte_carlo", no_monte_carlo)
    result = _invoke("verify", *SMALL, "--out", out)
    _one_line_error(result, f"--out {out}: figures is a file where kalcal writes a folder")
    assert _tree(out) == {"figures": b"mine"}


def test_report_names_its_folder_argument_and_how_to_adopt_an_old_folder(previous):
    """A run folder from a kalcal version without manifests: `kalcal report DIR` has no --out to change."""
    out, _ = previous
    (out / MANIFEST).unlink()
    result = _invoke("report", out)
    _one_line_error(
        result, f"kalcal: error: {out}: report.html was not written by kalcal here", "move report.html and figures/ out of it"
    )
    assert "--out" not in result.stderr
    # doing as it says adopts the folder: the page is drawn, and the manifest lists the page and figures
    (out / "report.html").unlink()
    shutil.rmtree(out / "figures")
    _ok("report", out)
    manifest = read_manifest(out)
    assert manifest.complete and "report.html" in manifest.files
    assert set(manifest.files) == {"report.html", *(f for f in _tree(out) if f.startswith("figures/"))}


def test_a_failing_first_run_removes_every_folder_it_created(tmp_path):
    (tmp_path / "bad.csv").write_text("time,accel\n0,not a number\n")
    out = tmp_path / "a" / "b" / "c"
    bad = tmp_path / "bad.csv"
    result = _invoke("calibrate", "accel-gps", "--imu", bad, "--gps", bad, "--out", out)
    assert result.exit_code == 2, result.output
    assert str(bad) in result.stderr and "accel" in result.stderr  # the job read the log: a/b/c had been created
    assert not (tmp_path / "a").exists()


def test_ctrl_c_while_the_figures_are_drawn_is_one_line_and_leaves_nothing(tmp_path):
    """Ctrl-C (SIGINT to the whole process group) once the page's first figure is staged: exit status 130
    and one line, the folder removed, and nothing appears in it afterwards."""
    out = tmp_path / "out"
    process, stderr = _interrupted(
        ["verify", "-n", "3000", "--set", "scenario.duration=20", "--out", str(out)],
        out, ".kalcal-partial-*/figures/*.png", within=120, poll=0.005,
    )  # fmt: skip
    assert process.returncode == 130, stderr
    assert stderr.splitlines() == ["kalcal: interrupted"]
    assert not out.exists()
    time.sleep(1.0)
    assert not out.exists()
    if sys.platform.startswith("linux"):  # nothing of the job's session outlives it
        assert _session(process.pid) == [], "a process of the job's session outlived it"


def _interrupted(args: list[str], out, staged: str, *, within: float, settle: float = 0.0, poll: float):
    """``python -m kalcal.cli ARGS`` in a session of its own, sent SIGINT to its whole process group (as the
    terminal's Ctrl-C) once ``out`` holds a path matching ``staged`` (and ``settle`` s more): the process,
    ended, and its stderr. It must still be running then, and the path must have appeared within
    ``within`` s; a process that outlives the interrupt is killed."""
    process = subprocess.Popen(
        [sys.executable, "-m", "kalcal.cli", *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + within
        while not list(out.glob(staged)) and process.poll() is None and time.monotonic() < deadline:
            time.sleep(poll)
        assert process.poll() is None, process.communicate()
        assert list(out.glob(staged)), f"nothing matching {staged} appeared in {within} s"
        time.sleep(settle)
        os.killpg(process.pid, signal.SIGINT)
        _, stderr = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
    return process, stderr


def _session(sid: int) -> list[int]:
    """The live processes of session ``sid``."""
    members = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            with contextlib.suppress(OSError):
                if os.getsid(int(entry)) == sid:
                    members.append(int(entry))
    return members
