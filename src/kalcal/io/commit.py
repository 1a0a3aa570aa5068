"""Putting a staged set of outputs in place: marked incomplete, old files removed, new ones renamed, marked complete."""

from __future__ import annotations

import contextlib
import errno
import fnmatch
import os
import shutil
import stat
from pathlib import Path

from kalcal.interrupts import deferred_signals
from kalcal.io.manifest import MANIFEST, Manifest, OutputError, fsync_folder, write_manifest
from kalcal.io.output_rules import check_targets, folder_name, inside, resolved
from kalcal.io.staging import STAGING_MARKER

__all__ = ["commit", "reason"]


def reason(exc: OSError) -> str:
    """The operating system's words for ``exc`` (``"No space left on device"``)."""
    return exc.strerror or type(exc).__name__


def _cause(exc: OSError) -> str:
    names = " -> ".join(str(f) for f in (exc.filename, exc.filename2) if f is not None)
    return f"{reason(exc)}: {names}" if names else reason(exc)


def _staged_files(staging: Path) -> list[str]:
    files = []
    for root, directories, names in os.walk(staging):
        for name in names + [d for d in directories if os.path.islink(os.path.join(root, d))]:
            files.append(Path(root, name).relative_to(staging).as_posix())
    return sorted(f for f in files if f != STAGING_MARKER)


def _require_marker(out: Path, staging: Path, marker: str | None, option: str | None) -> None:
    """The staging folder is the one this run made: a real folder holding its marker with the run's token.

    A folder that vanished while the run wrote (removed by another process) and was made again by a
    writer creating its parents holds part of the set or none of it: it is never committed.
    """
    if marker is None:
        return
    try:
        real = staging.is_dir() and not staging.is_symlink()
        found = (staging / STAGING_MARKER).read_text(encoding="utf-8").strip() if real else None
    except OSError:
        found = None
    if found != marker:
        raise OutputError(
            f"{folder_name(out, option)}: the run's staging folder {staging.name} was removed while the run wrote "
            "into it (by another process); its set is incomplete and was not put in place; the folder is unchanged: "
            "run again"
        )


def _fsync_files(staging: Path, new: list[str]) -> None:
    """Every staged file's data on disk (a link has no data of its own: its folder's entry is synced)."""
    for relative in new:
        path = staging / relative
        if path.is_symlink():
            continue
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _fsync_folders(root: Path, relatives: list[str]) -> None:
    """The entries renamed into (or removed from) ``root``'s subfolders on disk: every folder on their way, ``root`` last."""
    folders = {Path(relative).parent for relative in relatives}
    for folder in list(folders):
        folders.update(folder.parents)
    for folder in sorted(folders, key=lambda f: (-len(f.parts), f.as_posix())):
        if (root / folder).is_dir():
            fsync_folder(root / folder)


def _outside(path: Path) -> OSError:
    return OSError(errno.EXDEV, "a folder on its way is a symbolic link out of the folder", str(path))


def _make_folders(out: Path, relative: str) -> None:
    """The folders of ``out/relative`` made one level at a time, each level opened without following a link.

    Each level is made (``mkdir`` relative to the open folder above it) and then opened with
    ``O_NOFOLLOW``: a level that is a symbolic link (one made after the checks) stops the commit before
    anything is made beyond it, so no folder is ever created outside ``out``. (``mkdir(parents=True)``
    followed the link and made ``elsewhere/deep/`` before the check that refused the file.)
    """
    parts = Path(relative).parent.parts
    if not parts:
        return
    fd = os.open(resolved(out), os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    try:
        for depth, part in enumerate(parts):
            with contextlib.suppress(FileExistsError):
                os.mkdir(part, dir_fd=fd)  # never through a link: mkdir does not follow its last component
            try:
                child = os.open(part, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC, dir_fd=fd)
            except OSError:
                if stat.S_ISLNK(os.stat(part, dir_fd=fd, follow_symlinks=False).st_mode):
                    raise _outside(Path(out, *parts[: depth + 1])) from None
                raise
            os.close(fd)
            fd = child
    finally:
        os.close(fd)


def _remove(out: Path, relative: str) -> None:
    root = Path(resolved(out))
    path = root / relative
    if not inside(root, relative):
        raise _outside(path)  # never a file outside OUT (a subfolder replaced by a link after the checks)
    if path.is_symlink() or path.is_file():
        path.unlink()
    parent = path.parent
    while parent != root and root in parent.parents:
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
    *,
    marker: str | None = None,
) -> None:
    """Put the files staged in ``staging`` in place in ``out`` as one set, or raise and say what is left.

    ``listed`` are the files the manifests of ``out`` list (``old`` its own manifest); ``replaces`` None
    replaces the whole previous set, else glob patterns of the previous files replaced (the others stay,
    and so does ``old``'s command). Files in ``protected_paths`` (resolved) are never removed or replaced.
    SIGINT and SIGTERM wait until the set is whole. ``marker``: the token the run wrote into
    ``staging/.kalcal-staging`` (None: not required); a staging folder without it is never committed.
    The new files, the folders they are renamed into and ``out`` are synced to disk before the manifest
    says complete. Raises :class:`OutputError`, saying whether the folder is unchanged or marked incomplete.
    """
    _require_marker(out, staging, marker, option)
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
    try:
        _fsync_files(staging, new)
    except OSError as exc:
        raise OutputError(
            f"{folder_name(out, option)}: cannot write the new files to disk ({_cause(exc)}); the folder is unchanged"
        ) from None
    marked = False
    try:
        with deferred_signals():
            write_manifest(out, command, listed | new_set, complete=False)
            marked = True
            for relative in sorted(removed):
                _remove(out, relative)
            for relative in new:
                target = out / relative
                _make_folders(out, relative)
                if not inside(out, relative):  # a link made since: never a rename outside OUT
                    raise _outside(target)
                os.replace(staging / relative, target)
            _fsync_folders(out, [*new, *removed])
            write_manifest(out, command, kept | new_set, complete=True)
    except OSError as exc:
        cause = _cause(exc)
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
    if not staging.is_symlink():
        shutil.rmtree(staging, ignore_errors=True)
