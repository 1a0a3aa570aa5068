"""An output folder no second run, vanished staging folder, symbolic link or crash can corrupt (docs/outputs.md).

The cases about processes run real ones: a run held at a barrier file (inside its job, or inside its
commit) while a second run, the command line, tries the same folder; a run of another host (its host
name set in the process) killed while staging, whose folder the next run here must leave alone.
"""

from __future__ import annotations

import errno
import os
import re
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from kalcal.io import commit as commit_module
from kalcal.io import lock as lock_module
from kalcal.io import manifest as manifest_module
from kalcal.io.lock import LOCK, host_name
from kalcal.io.manifest import MANIFEST, read_manifest
from kalcal.io.outputs import OutputError, run_outputs
from tests._helpers import tree as _tree

COMMAND = "simulate scale-bias"  # the held run and the command line write the same command's set

# A run into argv[1] that writes A's set, touches the barrier file argv[2] and waits for argv[3] to exist:
# inside its job ("staging") or inside its commit, just before the manifest says complete ("commit").
# argv[4] is the host name the process reports ("-": its own).
HELD_RUN = textwrap.dedent(
    """
    import os, pathlib, socket, sys, time
    out, barrier, release, host, where = sys.argv[1:6]
    if host != "-":
        socket.gethostname = lambda: host
    from kalcal.io import commit as commit_module
    from kalcal.io.outputs import run_outputs

    def hold():
        pathlib.Path(barrier).touch()
        deadline = time.monotonic() + 60
        while not os.path.exists(release):
            if time.monotonic() > deadline:
                sys.exit("the barrier was never released")
            time.sleep(0.01)

    if where == "commit":
        real = commit_module.write_manifest
        def held(folder, command, files, *, complete=True):
            if complete:
                hold()
            return real(folder, command, files, complete=complete)
        commit_module.write_manifest = held
    with run_outputs(out, "simulate scale-bias") as staging:
        (staging / "data.csv").write_text("A's data\\n")
        (staging / "truth.json").write_text('{"run": "A"}\\n')
        if where == "staging":
            hold()
    """
)


def _wait_for(path: Path, process: subprocess.Popen, within: float = 60.0) -> None:
    deadline = time.monotonic() + within
    while not path.exists():
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline, f"{path} never appeared"
        time.sleep(0.01)


def _held_run(tmp_path: Path, out: Path, where: str, host: str = "-") -> tuple[subprocess.Popen, Path, Path]:
    barrier, release = tmp_path / f"barrier-{where}-{host}", tmp_path / f"release-{where}-{host}"
    process = subprocess.Popen(
        [sys.executable, "-c", HELD_RUN, str(out), str(barrier), str(release), host, where],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    _wait_for(barrier, process)
    return process, barrier, release


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "kalcal.cli", *args], capture_output=True, text=True, timeout=120, check=False
    )


def _write(folder: Path, files: dict[str, str]) -> None:
    for name, text in files.items():
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


def _run(out: Path, files: dict[str, str], command: str = "test", **options) -> None:
    with run_outputs(out, command, **options) as staging:
        _write(staging, files)


@pytest.mark.parametrize("where", ["staging", "commit"])
def test_a_second_run_while_the_first_holds_the_folder_refuses_in_one_line_naming_its_host_and_pid(tmp_path, where):
    """Two real processes: the first held at a barrier in its job or in its commit; the command line refuses."""
    out = tmp_path / "out"
    assert _cli("simulate", "scale-bias", "--out", str(out), "--seed", "1").returncode == 0
    first, _, release = _held_run(tmp_path, out, where)
    try:
        during = _tree(out)
        second = _cli("simulate", "scale-bias", "--out", str(out), "--seed", "2")
        assert second.returncode == 2, (second.stdout, second.stderr)
        assert second.stderr.splitlines() == [
            f"kalcal: error: --out {out}: another kalcal run is writing into this folder "
            f"(host {host_name()}, pid {first.pid}, {LOCK}); wait for it to end or choose another --out"
        ]
        assert _tree(out) == during  # the refused run changed nothing, the held run's staging included
    finally:
        release.touch()
        _, stderr = first.communicate(timeout=60)
    assert first.returncode == 0, stderr
    # the folder holds the first run's set, whole, and nothing of the refused one
    assert _tree(out) == {
        "data.csv": b"A's data\n", "truth.json": b'{"run": "A"}\n', MANIFEST: (out / MANIFEST).read_bytes(),
    }
    assert read_manifest(out).complete
    # and once the first run has ended, the folder is free again
    assert _cli("simulate", "scale-bias", "--out", str(out), "--seed", "2").returncode == 0
    assert read_manifest(out).complete and not (out / LOCK).exists()


def test_another_hosts_staging_folder_survives_and_a_dead_run_of_this_host_is_cleaned(tmp_path):
    """A run of another host (a container with its own name on a shared disk) killed while staging: its pid
    means nothing here, so the next run here leaves its folder alone; a killed run of this host is cleaned."""
    out = tmp_path / "out"
    out.mkdir()
    foreign, _, _ = _held_run(tmp_path, out, "staging", host="another-host")
    foreign.send_signal(signal.SIGKILL)
    foreign.communicate(timeout=60)
    [foreign_staging] = out.glob(".kalcal-partial-*")
    local, _, _ = _held_run(tmp_path, out, "staging")
    local.send_signal(signal.SIGKILL)
    local.communicate(timeout=60)
    [local_staging] = set(out.glob(".kalcal-partial-*")) - {foreign_staging}
    foreign_files = _tree(foreign_staging)
    assert "data.csv" in foreign_files
    assert (out / LOCK).exists()  # left by the killed runs: the kernel released their locks

    result = _cli("simulate", "scale-bias", "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert _tree(foreign_staging) == foreign_files
    assert not local_staging.exists()
    # the names that tell them apart; the lock file, taken over and removed by the run
    assert foreign_staging.name.startswith(f".kalcal-partial-another-host-{foreign.pid}-")
    assert local_staging.name.startswith(f".kalcal-partial-{host_name()}-{local.pid}-")
    assert not (out / LOCK).exists()
    assert read_manifest(out).complete


def test_the_lock_is_refused_within_one_process_too_and_released_after_a_failed_run(tmp_path):
    out = tmp_path / "out"
    with run_outputs(out, "test") as staging:
        with pytest.raises(OutputError) as caught:
            _run(out, {"a": "b"})
        assert f"(host {host_name()}, pid {os.getpid()}, {LOCK})" in str(caught.value)
        assert staging.name.startswith(f".kalcal-partial-{host_name()}-{os.getpid()}-")
        _write(staging, {"a": "first"})
    assert _tree(out).keys() == {"a", MANIFEST}
    with pytest.raises(RuntimeError):
        with run_outputs(out, "test"):
            raise RuntimeError("boom")
    _run(out, {"a": "third"})  # the failed run released the lock
    assert not (out / LOCK).exists() and (out / "a").read_text() == "third"


def test_a_redraw_in_a_sweeps_run_folder_is_refused_while_a_sweep_holds_the_sweeps_folder(tmp_path):
    out = tmp_path / "sweep"
    with run_outputs(out, "sweep") as staging:
        _run(staging / "key=1", {"summary.json": "1"}, command="verify")
    with run_outputs(out, "sweep") as staging:
        with pytest.raises(OutputError) as caught:
            _run(out / "key=1", {"report.html": "p"}, command="report", replaces=("report.html",), option=None)
        assert str(caught.value) == (
            f"{out / 'key=1'}: the enclosing folder {out}: another kalcal run is writing into this folder "
            f"(host {host_name()}, pid {os.getpid()}, {LOCK}); wait for it to end or choose another folder"
        )
        _run(staging / "key=2", {"summary.json": "2"}, command="verify")
    assert _tree(out).keys() == {"key=2/summary.json", f"key=2/{MANIFEST}", MANIFEST}
    _run(out / "key=2", {"report.html": "p"}, command="report", replaces=("report.html",), option=None)
    assert (out / "key=2" / "report.html").read_text() == "p" and not (out / LOCK).exists()


def test_a_folder_that_cannot_be_locked_is_refused_in_one_line(tmp_path, monkeypatch):
    def no_locks(fd, operation):
        raise OSError(errno.ENOLCK, "No locks available")

    monkeypatch.setattr(lock_module.fcntl, "flock", no_locks)
    with pytest.raises(OutputError, match=r"cannot lock the folder \(No locks available: .*does not support flock"):
        _run(tmp_path / "out", {"a": "b"})
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("made_again", [False, True])
def test_a_vanished_staging_folder_fails_the_run_and_leaves_the_previous_set(tmp_path, made_again):
    """Removed while the run writes (and made again by a writer creating its parents): never committed."""
    out = tmp_path / "out"
    _run(out, {"summary.json": "first", "figures/a.png": "a"})
    before = _tree(out)
    with pytest.raises(OutputError) as caught:
        with run_outputs(out, "test") as staging:
            _write(staging, {"summary.json": "second"})
            shutil.rmtree(staging)
            if made_again:
                _write(staging, {"figures/b.png": "half a set"})
    assert str(caught.value) == (
        f"--out {out}: the run's staging folder {staging.name} was removed while the run wrote into it (by another "
        "process); its set is incomplete and was not put in place; the folder is unchanged: run again"
    )
    assert _tree(out) == before and read_manifest(out).complete
    assert not list(out.glob(".kalcal-partial-*"))


def _linked_figures(tmp_path: Path) -> tuple[Path, Path, dict[str, bytes]]:
    """A set with figures/, then figures/ moved elsewhere (17 figures there) and replaced by a link to it."""
    out = tmp_path / "out"
    _run(out, {"summary.json": "s", **{f"figures/f{i}.png": f"run {i}" for i in range(17)}})
    elsewhere = tmp_path / "elsewhere"
    shutil.move(out / "figures", elsewhere)
    (out / "figures").symlink_to(elsewhere, target_is_directory=True)
    return out, elsewhere, _tree(elsewhere)


def test_a_subfolder_replaced_by_a_link_stops_the_rerun_and_no_file_outside_out_is_touched(tmp_path):
    out, elsewhere, outside = _linked_figures(tmp_path)
    before = _tree(out)
    ran = []
    with pytest.raises(OutputError) as caught:
        with run_outputs(out, "test") as staging:
            ran.append(True)
            _write(staging, {"summary.json": "s2"})
    assert str(caught.value) == (
        f"--out {out}: figures is a symbolic link where kalcal writes a folder (kalcal removes and writes files only "
        "inside the folder); replace it with a folder or choose another --out"
    )
    assert not ran and _tree(elsewhere) == outside and len(outside) == 17 and _tree(out) == before


def test_a_link_made_while_the_run_writes_is_refused_at_the_commit(tmp_path):
    out, elsewhere, outside = _linked_figures(tmp_path)
    (out / "figures").unlink()
    _run(out, {"summary.json": "s2"})  # a set without figures/
    with pytest.raises(OutputError, match="figures is a symbolic link where kalcal writes a folder"):
        with run_outputs(out, "test") as staging:
            _write(staging, {"summary.json": "s3", "figures/new.png": "n"})
            (out / "figures").symlink_to(elsewhere, target_is_directory=True)
    assert _tree(elsewhere) == outside and (out / "summary.json").read_text() == "s2"


def test_a_removal_through_a_link_made_after_the_checks_is_not_done(tmp_path):
    """The last guard: the resolved path of every removal is under OUT, else the commit stops (marked incomplete)."""
    out, elsewhere, outside = _linked_figures(tmp_path)
    with pytest.raises(OSError, match="symbolic link out of the folder"):
        commit_module._remove(out, "figures/f3.png")
    assert _tree(elsewhere) == outside


def test_a_link_made_after_the_commits_checks_stops_it_marked_incomplete_and_removes_nothing_outside(
    tmp_path, monkeypatch
):
    out, elsewhere, outside = _linked_figures(tmp_path)
    (out / "figures").unlink()
    (out / "figures").mkdir()
    for name in outside:
        (out / "figures" / name).write_text("back in place")
    real_check = commit_module.check_targets

    def check_then_link(*args, **kwargs):
        real_check(*args, **kwargs)
        shutil.rmtree(out / "figures")
        (out / "figures").symlink_to(elsewhere, target_is_directory=True)

    monkeypatch.setattr(commit_module, "check_targets", check_then_link)
    with pytest.raises(OutputError) as caught:
        _run(out, {"summary.json": "s2"})
    message = str(caught.value)
    assert message.startswith(
        f"--out {out}: putting the new files in place failed (a folder on its way is a symbolic link out of the folder: "
    )
    assert "marked incomplete" in message and not read_manifest(out).complete
    assert _tree(elsewhere) == outside


@pytest.mark.parametrize("linked", ["figures", "figures/deep"])
def test_a_link_made_after_the_commits_checks_creates_no_folder_outside(tmp_path, monkeypatch, linked):
    """A new file two folders deep, and a level on its way replaced by a link after the checks: the
    commit stops marked incomplete and the link's target stays empty (2114039's fix made its folders with
    mkdir(parents=True) before checking, creating elsewhere/deep/ or elsewhere/more/)."""
    out = tmp_path / "out"
    _run(out, {"summary.json": "s"})
    (out / "figures").mkdir()  # a user's folder: the set lists nothing in it
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    real_check = commit_module.check_targets

    def check_then_link(*args, **kwargs):
        real_check(*args, **kwargs)
        shutil.rmtree(out / "figures")
        if linked == "figures/deep":
            (out / "figures").mkdir()
        (out / linked).symlink_to(elsewhere, target_is_directory=True)

    monkeypatch.setattr(commit_module, "check_targets", check_then_link)
    with pytest.raises(OutputError, match=rf"a symbolic link out of the folder: {re.escape(str(out / linked))}\); "):
        _run(out, {"summary.json": "s2", "figures/deep/more/b.png": "b"})
    assert list(elsewhere.iterdir()) == []
    assert not read_manifest(out).complete


def test_out_itself_may_be_a_link(tmp_path):
    real = tmp_path / "real"
    real.mkdir()
    link = tmp_path / "link"
    link.symlink_to(real, target_is_directory=True)
    _run(link, {"figures/a.png": "a", "summary.json": "1"})
    _run(link, {"summary.json": "2"})
    assert _tree(real) == {"summary.json": b"2", MANIFEST: (real / MANIFEST).read_bytes()}


def test_a_listed_file_replaced_by_a_link_is_removed_as_a_link(tmp_path):
    out = tmp_path / "out"
    _run(out, {"summary.json": "s", "stats.nc": "n"})
    precious = tmp_path / "precious.nc"
    precious.write_text("not kalcal's")
    (out / "stats.nc").unlink()
    (out / "stats.nc").symlink_to(precious)
    _run(out, {"summary.json": "s2"})
    assert precious.read_text() == "not kalcal's" and not os.path.lexists(out / "stats.nc")


def test_every_file_and_folder_is_synced_before_the_manifest_says_complete(tmp_path, monkeypatch):
    out = tmp_path / "out"
    _run(out, {"old/x.png": "old"})
    events = []
    real_fsync, real_write = os.fsync, commit_module.write_manifest

    def fsync(fd):
        events.append(("fsync", os.readlink(f"/proc/self/fd/{fd}")))
        real_fsync(fd)

    def write_manifest(folder, command, files, *, complete=True):
        events.append(("manifest", complete))
        return real_write(folder, command, files, complete=complete)

    monkeypatch.setattr(manifest_module.os, "fsync", fsync)
    monkeypatch.setattr(commit_module, "write_manifest", write_manifest)
    with run_outputs(out, "test") as staging:
        _write(staging, {"summary.json": "s", "figures/a.png": "a", "figures/deep/b.png": "b"})
    marked, complete = events.index(("manifest", False)), events.index(("manifest", True))
    # the files' data, synced in the staging folder before the folder is marked incomplete
    before_marking = {path for kind, path in events[:marked] if kind == "fsync"}
    for name in ("summary.json", "figures/a.png", "figures/deep/b.png"):
        assert str(staging / name) in before_marking, name
    # then, after the renames, the folders renamed into and removed from, deepest first, OUT last
    root = os.path.realpath(out)
    folders = [path for kind, path in events[marked + 1 : complete] if kind == "fsync" and not path.endswith(".tmp")]
    assert folders[-1] == root
    assert {f"{root}/figures", f"{root}/figures/deep"} <= set(folders)
    assert folders.index(f"{root}/figures/deep") < folders.index(f"{root}/figures")
    # the manifest itself: its bytes synced before the rename, and the folder after it
    after = [path for kind, path in events[complete:] if kind == "fsync"]
    assert after[0].endswith(f"{MANIFEST}.tmp") and after[-1] == root


def test_a_refused_verify_with_workers_starts_no_dask_cluster(tmp_path, monkeypatch):
    """The folder is locked before the run's Dask cluster starts: a second ``verify --workers`` into a held
    folder is refused without paying for a cluster (docs/outputs.md: it stops before it starts)."""
    import kalcal
    from kalcal.montecarlo import distributed

    started = []

    def no_cluster(*args, **kwargs):
        started.append(args)
        raise AssertionError("a Dask cluster was started for a refused run")

    monkeypatch.setattr(distributed, "dask_client", no_cluster)
    out = tmp_path / "out"
    with run_outputs(out, "verify"):
        with pytest.raises(OutputError, match="another kalcal run is writing into this folder"):
            kalcal.verify(n=1000, workers=2, out=out, report=False)
    assert started == []
