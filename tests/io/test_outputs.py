"""``kalcal.io.outputs``: a folder holds one run's set of outputs, whole, and never a user's file is touched."""

from __future__ import annotations

import json
import os
import signal
import tempfile
from dataclasses import dataclass
from pathlib import Path

import pytest

from kalcal.interrupts import Interrupted, deferred_signals, raise_on_signals
from kalcal.io import commit, outputs
from kalcal.io.manifest import MANIFEST, Manifest, listed_files, read_manifest, require_complete, write_manifest
from kalcal.io.outputs import OutputError, final_path, protected, run_outputs, writes_outputs
from tests._helpers import tree as _tree


def _write(folder: Path, files: dict[str, str]) -> None:
    for name, text in files.items():
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


def _run(out: Path, files: dict[str, str], command: str = "test", **options) -> None:
    with run_outputs(out, command, **options) as staging:
        _write(staging, files)


def test_a_set_is_committed_with_its_manifest(tmp_path):
    out = tmp_path / "new" / "out"
    _run(out, {"summary.json": "1", "figures/a.png": "a"})
    assert _tree(out).keys() == {"summary.json", "figures/a.png", MANIFEST}
    manifest = read_manifest(out)
    assert manifest.complete and manifest.command == "test"
    assert manifest.files == ("figures/a.png", "summary.json")


def test_a_second_set_replaces_the_first_whole_and_leaves_other_files(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")  # the user's own file, `--out .` style
    (out / "figures").mkdir()
    (out / "figures" / "mine.svg").write_text("mine too")
    _run(out, {"summary.json": "first", "stats_long.nc": "first", "figures/a.png": "a", "figures/b.png": "b"})
    _run(out, {"summary.json": "second", "figures/a.png": "a2"})
    assert _tree(out) == {
        "notes.txt": b"mine",
        "figures/mine.svg": b"mine too",
        "summary.json": b"second",
        "figures/a.png": b"a2",
        MANIFEST: (out / MANIFEST).read_bytes(),
    }
    assert read_manifest(out).files == ("figures/a.png", "summary.json")


def test_an_emptied_subfolder_is_removed_but_not_one_with_a_user_file(tmp_path):
    out = tmp_path / "out"
    _run(out, {"figures/a.png": "a", "keep/b.png": "b"})
    (out / "keep" / "user.txt").write_text("mine")
    _run(out, {"summary.json": "x"})
    assert not (out / "figures").exists()
    assert _tree(out).keys() == {"keep/user.txt", "summary.json", MANIFEST}


@pytest.mark.parametrize("error", [RuntimeError("a writer failed"), KeyboardInterrupt(), Interrupted(signal.SIGTERM)])
def test_a_failed_or_interrupted_run_leaves_the_previous_set_byte_identical(tmp_path, error):
    out = tmp_path / "out"
    _run(out, {"summary.json": "seed 0, PASS", "report.html": "PASS page"})
    (out / "user.txt").write_text("mine")
    before = _tree(out)
    with pytest.raises(type(error)):
        with run_outputs(out, "test") as staging:
            _write(staging, {"summary.json": "seed 7, FAIL"})
            raise error
    assert _tree(out) == before
    assert not list(out.glob(".kalcal-partial-*"))


def test_a_failed_first_run_leaves_no_folder(tmp_path):
    out = tmp_path / "fresh"
    with pytest.raises(RuntimeError):
        with run_outputs(out, "test") as staging:
            _write(staging, {"summary.json": "x"})
            raise RuntimeError("boom")
    assert not out.exists()


def test_a_file_named_like_an_output_that_no_manifest_lists_stops_the_run_before_it_starts(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "summary.json").write_text("the user's own")
    ran = []
    with pytest.raises(OutputError, match=r"summary\.json was not written by kalcal here"):
        with run_outputs(out, "test", names=("summary.json", "stats.nc")):
            ran.append(True)
    assert not ran and (out / "summary.json").read_text() == "the user's own"
    assert _tree(out).keys() == {"summary.json"}


def test_a_file_the_set_would_replace_that_no_manifest_lists_is_refused_at_commit(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "other.csv").write_text("the user's own")
    with pytest.raises(OutputError, match="other.csv was not written by kalcal here"):
        _run(out, {"other.csv": "kalcal's"})
    assert _tree(out) == {"other.csv": b"the user's own"}


def test_inputs_are_never_removed_or_replaced(tmp_path):
    out = tmp_path / "out"
    _run(out, {"data.csv": "simulated", "truth.json": "t"})
    # calibrating the simulated log into the same folder: its input stays, the rest of the old set goes
    _run(out, {"summary.json": "cal"}, protect=[out / "data.csv"])
    assert _tree(out).keys() == {"data.csv", "summary.json", MANIFEST}
    assert set(read_manifest(out).files) == {"data.csv", "summary.json"}
    with protected(out / "data.csv"):
        with pytest.raises(OutputError, match="would replace its own input"):
            _run(out, {"data.csv": "new"})
        with pytest.raises(OutputError, match="would replace its own input"):
            _run(out, {"x": "y"}, names=("data.csv",))
    assert (out / "data.csv").read_text() == "simulated"


def test_out_that_is_a_file_or_cannot_be_created_or_written(tmp_path, monkeypatch):
    blocker = tmp_path / "blocker"
    blocker.write_text("")
    with pytest.raises(OutputError, match=rf"--out {blocker}: is an existing file, not a folder"):
        _run(blocker, {"a": "b"})
    with pytest.raises(OutputError, match=rf"--out {blocker / 'sub'}: cannot create the folder \("):
        _run(blocker / "sub", {"a": "b"})

    def refuse(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(tempfile, "mkdtemp", refuse)
    with pytest.raises(OutputError, match=rf"--out {tmp_path}: cannot write in the folder \(Permission denied\)"):
        _run(tmp_path, {"a": "b"})


def test_a_folder_where_a_file_should_be_is_refused(tmp_path):
    out = tmp_path / "out"
    (out / "summary.json").mkdir(parents=True)
    with pytest.raises(OutputError, match="summary.json is a folder where kalcal writes a file"):
        _run(out, {"summary.json": "x"})
    assert (out / "summary.json").is_dir()


def test_a_commit_cut_short_is_marked_incomplete_and_the_next_run_cleans_both_sets(tmp_path, monkeypatch):
    out = tmp_path / "out"
    _run(out, {"old.png": "old", "both.json": "old"})
    real_replace = os.replace
    moved = []

    def die_after_one(source, target):
        if not str(target).endswith(MANIFEST) and moved:
            raise OSError(28, "No space left on device", str(source), None, str(target))
        moved.append(target)
        real_replace(source, target)

    monkeypatch.setattr(outputs.os, "replace", die_after_one)
    # one line naming the folder, the file and the cause, and saying what state the folder is in
    with pytest.raises(OutputError) as caught:
        _run(out, {"both.json": "new", "new.png": "new", "z.csv": "new"})
    message = str(caught.value)
    assert message.startswith(f"--out {out}: putting the new files in place failed (No space left on device: ")
    assert f"{out / 'both.json'}" in message and "marked incomplete" in message and "run again" in message
    monkeypatch.setattr(outputs.os, "replace", real_replace)
    manifest = read_manifest(out)
    assert not manifest.complete
    assert set(manifest.files) == {"old.png", "both.json", "new.png", "z.csv"}
    with pytest.raises(OutputError, match="incomplete"):
        require_complete(out)
    with pytest.raises(OutputError, match="incomplete"):
        _run(out, {"report.html": "x"}, replaces=("report.html",))
    _run(out, {"summary.json": "third"})
    assert _tree(out).keys() == {"summary.json", MANIFEST} and read_manifest(out).complete


def test_a_commit_whose_first_manifest_cannot_be_written_leaves_the_folder_unchanged(tmp_path, monkeypatch):
    out = tmp_path / "out"
    _run(out, {"old.png": "old"})
    before = _tree(out)

    def full(source, target):
        raise OSError(28, "No space left on device", str(source), None, str(target))

    monkeypatch.setattr(outputs.os, "replace", full)
    unchanged = rf"--out {out}: cannot write {MANIFEST} \(No space left on device: .*; the folder is unchanged$"
    with pytest.raises(OutputError, match=unchanged):
        _run(out, {"new.png": "new"})
    assert _tree(out) == before


def test_a_redraw_replaces_only_its_own_files(tmp_path):
    out = tmp_path / "out"
    _run(out, {"summary.json": "s", "stats.nc": "n", "report.html": "p1", "figures/a.png": "a", "figures/b.png": "b"},
         command="verify")
    _run(out, {"report.html": "p2", "figures/a.png": "a2"}, command="report", replaces=("report.html", "figures/*"))
    assert _tree(out) == {
        "summary.json": b"s", "stats.nc": b"n", "report.html": b"p2", "figures/a.png": b"a2",
        MANIFEST: (out / MANIFEST).read_bytes(),
    }
    manifest = read_manifest(out)
    assert manifest.command == "verify" and set(manifest.files) == {"summary.json", "stats.nc", "report.html", "figures/a.png"}


def test_a_job_writing_into_the_staged_folder_joins_the_set_and_a_subfolder_commits_its_own(tmp_path):
    out = tmp_path / "out"
    with run_outputs(out, "sweep") as staging:
        with run_outputs(staging, "report") as joined:
            assert joined == staging
            _write(joined, {"report.html": "p"})
        with run_outputs(staging / "key=1", "verify") as inner:
            assert inner != staging / "key=1"
            _write(inner, {"summary.json": "1"})
            assert final_path(inner / "summary.json") == out / "key=1" / "summary.json"
        assert not (out / "report.html").exists()  # nothing in place before the outer set is committed
    assert _tree(out).keys() == {"report.html", "key=1/summary.json", f"key=1/{MANIFEST}", MANIFEST}
    assert read_manifest(out / "key=1").files == ("summary.json",)
    # a page later drawn in the subfolder is listed there, and the next outer set removes it too
    _run(out / "key=1", {"report.html": "p"}, replaces=("report.html",))
    assert "key=1/report.html" in listed_files(out)
    _run(out, {"sweep.csv": "2"}, command="sweep")
    assert _tree(out).keys() == {"sweep.csv", MANIFEST}


def test_the_decorator_hands_the_job_the_staging_folder_and_returns_final_paths(tmp_path):
    seen = []

    @writes_outputs("job", names=("a.txt",), inputs=("source",))
    def job(source, out, *, text="x"):
        seen.append(out)
        assert out.name.startswith(".kalcal-partial-")
        (out / "a.txt").write_text(text)
        return {"a": out / "a.txt", "nested": [out / "a.txt"], "input": source}

    source = tmp_path / "in.csv"
    source.write_text("input")
    result = job(source, tmp_path / "out", text="y")
    assert result == {"a": tmp_path / "out" / "a.txt", "nested": [tmp_path / "out" / "a.txt"], "input": source}
    assert (tmp_path / "out" / "a.txt").read_text() == "y"
    with pytest.raises(OutputError, match="would replace its own input"):
        job(tmp_path / "out" / "a.txt", tmp_path / "out")


@dataclass(frozen=True)
class _Outcome:
    paths: dict
    value: float


def test_paths_inside_a_returned_dataclass_are_moved_and_other_values_kept(tmp_path):
    @writes_outputs("job")
    def job(out):
        (out / "a.txt").write_text("a")
        return _Outcome({"a": out / "a.txt"}, 1.5)

    result = job(tmp_path / "out")
    assert result == _Outcome({"a": tmp_path / "out" / "a.txt"}, 1.5)


def test_staging_folders_of_dead_runs_on_this_host_are_removed_and_no_other(tmp_path):
    """A pid is only known on its own host: another host's staging folder, or one whose name has no host, stays."""
    from kalcal.io.lock import host_name

    out = tmp_path / "out"
    out.mkdir()
    host = host_name()
    dead = out / f".kalcal-partial-{host}-999999999-abc"
    alive = out / f".kalcal-partial-{host}-{os.getppid()}-abc"
    foreign = out / ".kalcal-partial-another-host-999999999-abc"
    nameless = out / ".kalcal-partial-999999999-abc"
    for folder in (dead, alive, foreign, nameless):
        folder.mkdir()
        (folder / "summary.json").write_text("half")
    _run(out, {"summary.json": "x"})
    assert not dead.exists()
    assert all((folder / "summary.json").read_text() == "half" for folder in (alive, foreign, nameless))


def test_a_manifest_kalcal_did_not_write_is_refused(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / MANIFEST).write_text("{}")
    with pytest.raises(OutputError, match="not a kalcal manifest"):
        _run(out, {"a": "b"})
    (out / MANIFEST).write_text(json.dumps({"command": "x", "complete": True, "files": ["../../etc/passwd"]}))
    with pytest.raises(OutputError, match="not a file inside the folder"):
        _run(out, {"a": "b"})


def test_write_manifest_lists_sorted_unique_files(tmp_path):
    write_manifest(tmp_path, "verify", ["b", "a", "b"], complete=False)
    manifest = read_manifest(tmp_path)
    assert manifest == Manifest("verify", False, ("a", "b"))


def test_signals_raise_interrupted_with_the_shell_status():
    with raise_on_signals():
        with pytest.raises(Interrupted) as caught:
            signal.raise_signal(signal.SIGTERM)
    assert caught.value.signum == signal.SIGTERM and caught.value.exit_status == 143
    assert Interrupted(signal.SIGINT).exit_status == 130
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL


def test_a_signal_during_the_commit_waits_for_it_to_end():
    done = []
    with raise_on_signals():
        with pytest.raises(Interrupted):
            with deferred_signals():
                signal.raise_signal(signal.SIGTERM)
                done.append("after the signal")
        assert done == ["after the signal"]


def test_a_signal_in_the_commit_still_leaves_a_whole_set(tmp_path, monkeypatch):
    out = tmp_path / "out"
    _run(out, {"a.txt": "old", "b.txt": "old"})
    real_remove = commit._remove

    def remove_and_signal(folder, relative):
        signal.raise_signal(signal.SIGTERM)
        real_remove(folder, relative)

    monkeypatch.setattr(commit, "_remove", remove_and_signal)
    with raise_on_signals(), pytest.raises(Interrupted):
        _run(out, {"a.txt": "new", "c.txt": "new"})
    assert _tree(out).keys() == {"a.txt", "c.txt", MANIFEST} and read_manifest(out).complete


def test_a_folder_holding_another_commands_outputs_is_refused_before_the_job_runs(tmp_path):
    out = tmp_path / "sim"
    _run(out, {"imu.csv": "i", "truth.csv": "t"}, command="simulate accel-gps")
    before = _tree(out)
    ran = []
    with pytest.raises(OutputError) as caught:
        with run_outputs(out, "calibrate accel-gps"):
            ran.append(True)
    assert str(caught.value) == f"--out {out}: holds the outputs of `kalcal simulate accel-gps`; choose another folder"
    assert not ran and _tree(out) == before
    # the same command replaces its own set, and a redraw (replaces=) adds to another command's set
    _run(out, {"imu.csv": "i2"}, command="simulate accel-gps")
    _run(out, {"report.html": "p"}, command="report", replaces=("report.html",))
    assert read_manifest(out).command == "simulate accel-gps"
    assert set(read_manifest(out).files) == {"imu.csv", "report.html"}


def test_a_file_where_the_outputs_need_a_folder_stops_the_run_before_it_starts(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "figures").write_text("the user's own")
    ran = []
    with pytest.raises(OutputError, match=rf"^--out {out}: figures is a file where kalcal writes a folder$"):
        with run_outputs(out, "test", names=("summary.json", "figures/*.png", "*=*/summary.json")):
            ran.append(True)
    assert not ran and _tree(out) == {"figures": b"the user's own"}
    # and at the commit, for a folder the names did not announce
    with pytest.raises(OutputError, match=r"figures is a file where kalcal writes a folder"):
        _run(out, {"figures/a.png": "x"})
    assert _tree(out) == {"figures": b"the user's own"}


def test_a_glob_match_no_manifest_lists_is_named_as_in_kalcals_place_not_as_replaced(tmp_path):
    out = tmp_path / "out"
    (out / "figures").mkdir(parents=True)
    (out / "figures" / "mine.png").write_text("the user's own")
    with pytest.raises(OutputError) as caught:
        _run(out, {"figures/a.png": "x"}, names=("figures/*.png",))
    message = str(caught.value)
    assert "figures/mine.png was not written by kalcal here" in message
    assert "is in a place kalcal writes into (figures/*.png)" in message and "replaced" not in message


def test_messages_name_a_folder_argument_without_out_and_say_the_remedy(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / "report.html").write_text("an old page")
    with pytest.raises(OutputError) as caught:
        _run(out, {"report.html": "p"}, names=("report.html",), option=None, remedy="move report.html away")
    assert str(caught.value).startswith(f"{out}: report.html was not written by kalcal here")
    assert str(caught.value).endswith("; move report.html away") and "--out" not in str(caught.value)


def test_a_failed_first_run_removes_every_folder_it_created(tmp_path):
    (tmp_path / "a").mkdir()
    out = tmp_path / "a" / "b" / "c" / "d"
    with pytest.raises(RuntimeError):
        with run_outputs(out, "test") as staging:
            _write(staging, {"summary.json": "x"})
            raise RuntimeError("boom")
    assert not (tmp_path / "a" / "b").exists() and (tmp_path / "a").is_dir()
    # a folder that something else wrote into meanwhile stays, with the folders above it
    with pytest.raises(RuntimeError):
        with run_outputs(out, "test") as staging:
            (tmp_path / "a" / "b" / "theirs.txt").write_text("not the run's")
            raise RuntimeError("boom")
    assert not (tmp_path / "a" / "b" / "c").exists() and (tmp_path / "a" / "b" / "theirs.txt").is_file()


@dataclass(frozen=True)
class _Scenario:
    duration: float = 1.0


def test_the_file_a_scenario_was_read_from_is_an_input_of_every_job_given_it(tmp_path):
    """A job called from Python (no command line) keeps the config its scenario was built from."""
    out = tmp_path / "out"
    _run(out, {"cfg.toml": "[scenario]\nduration = 2\n", "old.csv": "o"}, command="job")
    scenario = outputs.mark_inputs(_Scenario(), out / "cfg.toml")
    assert scenario == _Scenario() and repr(scenario) == repr(_Scenario())  # the settings are unchanged
    assert outputs.inputs_of(scenario) == (os.path.realpath(out / "cfg.toml"),)

    @writes_outputs("job")
    def job(scenario, out):
        (Path(out) / "new.csv").write_text("n")

    job(scenario, out)
    assert _tree(out).keys() == {"cfg.toml", "new.csv", MANIFEST}


def test_build_scenario_records_its_config(tmp_path):
    from kalcal.scenarios import build_scenario

    config = tmp_path / "cfg.toml"
    config.write_text("[scenario]\nduration = 2\n")
    assert outputs.inputs_of(build_scenario("accel-gps", config)) == (os.path.realpath(config),)
    assert outputs.inputs_of(build_scenario("accel-gps")) == ()
