"""The manifest of an output folder (``.kalcal-manifest.json``): what it says, reading and writing it.

The manifest lists the files the last kalcal command wrote into the folder, and whether that command
finished putting them in place (``"complete"``); the next run into the folder replaces exactly those
files (:mod:`kalcal.io.outputs`).
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from kalcal.errors import KalcalError

__all__ = [
    "MANIFEST",
    "MANIFEST_VERSION",
    "Manifest",
    "OutputError",
    "listed_files",
    "read_manifest",
    "require_complete",
    "fsync_folder",
    "write_manifest",
]

MANIFEST = ".kalcal-manifest.json"
MANIFEST_VERSION = 1


class OutputError(KalcalError):
    """An output folder cannot be used: a file in its place, not writable, or holding files kalcal did not write."""


@dataclass(frozen=True)
class Manifest:
    """What ``OUT/.kalcal-manifest.json`` says.

    Attributes
    ----------
    command : str
        The command that wrote the set (``"verify"``, ``"calibrate accel-gps"``, ...).
    complete : bool
        False while a commit is under way (or was cut short).
    files : tuple of str
        The files of the set, relative to the folder, with ``/`` separators.
    """

    command: str
    complete: bool
    files: tuple[str, ...]


def read_manifest(folder: str | Path) -> Manifest | None:
    """The manifest of ``folder``, None when it has none.

    Raises
    ------
    OutputError
        The manifest exists but is not one kalcal wrote (then which files are kalcal's is unknown).
    """
    path = Path(folder) / MANIFEST
    if not path.exists():
        return None
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
        files = document["files"]
        if not isinstance(files, list) or not all(isinstance(f, str) for f in files):
            raise TypeError("files is not a list of names")
        return Manifest(str(document["command"]), bool(document["complete"]), tuple(files))
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError) as exc:
        raise OutputError(f"{path}: not a kalcal manifest ({exc}); remove it or choose another folder") from None


def listed_files(folder: str | Path) -> set[str]:
    """Every file the manifests of ``folder`` list: its own, and those of the manifests it lists in subfolders."""
    folder = Path(folder)
    manifest = read_manifest(folder)
    if manifest is None:
        return set()
    files = {_safe_relative(name, folder) for name in manifest.files}
    for name in list(files):
        parts = name.split("/")
        if len(parts) > 1 and parts[-1] == MANIFEST:
            sub = "/".join(parts[:-1])
            files |= {f"{sub}/{inner}" for inner in listed_files(folder / sub)}
    return files


def require_complete(folder: str | Path) -> None:
    """Raise :class:`OutputError` when the last kalcal run into ``folder`` did not finish its commit."""
    manifest = read_manifest(folder)
    if manifest is not None and not manifest.complete:
        raise OutputError(
            f"{folder}: incomplete (the last kalcal run here, {manifest.command}, was stopped while putting its "
            f"files in place; {MANIFEST} says so); run it again"
        )


def _safe_relative(name: str, folder: Path) -> str:
    """A manifest entry as a normalized relative path inside the folder (a tampered '../x' is refused)."""
    normal = os.path.normpath(name).replace(os.sep, "/")
    if os.path.isabs(normal) or normal == ".." or normal.startswith("../") or normal in (".", ""):
        raise OutputError(f"{folder / MANIFEST}: entry {name!r} is not a file inside the folder")
    return normal


def write_manifest(folder: str | Path, command: str, files: Iterable[str], *, complete: bool = True) -> Path:
    """Write ``folder/.kalcal-manifest.json`` atomically (a temporary file, synced, then a rename, and the folder synced)."""
    from kalcal import __version__

    path = Path(folder) / MANIFEST
    document = {
        "manifest_version": MANIFEST_VERSION,
        "note": "the files the last kalcal command wrote here; the next one into this folder replaces exactly these",
        "command": command,
        "complete": complete,
        "kalcal_version": __version__,
        "files": sorted(set(files)),
    }
    temporary = path.with_name(path.name + ".tmp")
    with open(temporary, "w", encoding="utf-8") as stream:
        stream.write(json.dumps(document, indent=2) + "\n")
        stream.flush()
        os.fsync(stream.fileno())  # the manifest's bytes on disk before its name says what it says
    os.replace(temporary, path)
    fsync_folder(path.parent)
    return path


def fsync_folder(folder: str | Path) -> None:
    """Put ``folder``'s entries (names created, renamed or removed in it) on disk."""
    fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
