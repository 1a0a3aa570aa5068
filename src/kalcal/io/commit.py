"""Putting a staged set of outputs in place: marked incomplete, old files removed, new ones renamed, marked complete."""

from __future__ import annotations

import contextlib
import fnmatch
import os
import shutil
from pathlib import Path

from kalcal.interrupts import deferred_signals
from kalcal.io.manifest import MANIFEST, Manifest, OutputError, write_manifest
from kalcal.io.output_rules import check_targets, folder_name, resolved

__all__ = ["commit", "reason"]


def reason(exc: OSError) -> str:
    """The operating system's words for ``exc`` (``"No space left on device"``)."""
    return exc.strerror or type(exc).__name__


def _staged_files(staging: Path) -> list[str]:
    files = []
    for root, directories, names in os.walk(staging):
        for name in names + [d for d in directories if os.path.islink(os.path.join(root, d))]:
            files.append(Path(root, name).relative_to(staging).as_posix())
    return sorted(files)


def _remove(out: Path, relative: str) -> None:
    path = out / relative
    if path.is_symlink() or path.is_file():
        path.unlink()
    parent = path.parent
    while parent != out and out in parent.parents:
        try:
            parent.rmdir()  # only when empty: a user's file in a kalcal subfolder keeps it
        except OSError:
            break
        parent = parent.parent


def commit(
    out: Path,
    staging: Path,
    command: str,
    old: Manifest | None,
    listed: set[str],
    replaces: tuple[str, ...] | None,
    protected_paths: frozenset[str],
    option: str | None = "--out",
    remedy: str | None = None,
) -> None:
    """Put the files staged in ``staging`` in place in ``out`` as one set, or raise and say what is left.

    ``listed`` are the files the manifests of ``out`` list (``old`` its own manifest); ``replaces`` None
    replaces the whole previous set, else glob patterns of the previous files replaced (the others stay,
    and so does ``old``'s command). Files in ``protected_paths`` (resolved) are never removed or replaced.
    SIGINT and SIGTERM wait until the set is whole. Raises :class:`OutputError`, saying whether the folder
    is unchanged or marked incomplete.
    """
    new = _staged_files(staging)
    new_set = set(new)
    check_targets(out, new, listed, protected_paths, option, remedy)
    if replaces is None:
        replaced = set(listed)
    else:
        replaced = {f for f in listed if any(fnmatch.fnmatchcase(f, pattern) for pattern in replaces)}
    kept = listed - replaced
    removed = set()
    for relative in sorted(replaced - new_set):
        if resolved(out / relative) in protected_paths:
            kept.add(relative)  # an input of this run: it stays, and stays kalcal's
        else:
            removed.add(relative)
    if replaces is not None and old is not None:
        command = old.command  # a redraw adds to the run that is there
    marked = False
    try:
        with deferred_signals():
            write_manifest(out, command, listed | new_set, complete=False)
            marked = True
            for relative in sorted(removed):
                _remove(out, relative)
            for relative in new:
                target = out / relative
                target.parent.mkdir(parents=True, exist_ok=True)
                os.replace(staging / relative, target)
            write_manifest(out, command, kept | new_set, complete=True)
    except OSError as exc:
        names = " -> ".join(str(f) for f in (exc.filename, exc.filename2) if f is not None)
        cause = f"{reason(exc)}: {names}" if names else reason(exc)
        if not marked:
            with contextlib.suppress(OSError):
                (out / (MANIFEST + ".tmp")).unlink()
            raise OutputError(
                f"{folder_name(out, option)}: cannot write {MANIFEST} ({cause}); the folder is unchanged"
            ) from None
        raise OutputError(
            f"{folder_name(out, option)}: putting the new files in place failed ({cause}); the folder is marked "
            f"incomplete ({MANIFEST}): free the space or fix the cause and run again"
        ) from None
    shutil.rmtree(staging, ignore_errors=True)
