"""Staging folders: named by host and process, marked by their run, removed only when their run is provably gone."""

from __future__ import annotations

import os
import secrets
import shutil
import tempfile
from pathlib import Path

from kalcal.io.lock import host_name
from kalcal.io.output_rules import resolved

__all__ = ["PARTIAL_PREFIX", "STAGING_MARKER", "make_staging", "remove_stale_partials", "remove_staging"]

PARTIAL_PREFIX = ".kalcal-partial-"

# written by the run into its staging folder when it makes it; the commit requires it, with the run's token
STAGING_MARKER = ".kalcal-staging"


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _staging_owner(name: str) -> tuple[str, int] | None:
    """(host, pid) of a staging folder's name ``.kalcal-partial-<host>-<pid>-<random>``; None for another name."""
    parts = name[len(PARTIAL_PREFIX) :].rsplit("-", 2)
    if len(parts) != 3 or not parts[0] or not parts[1].isdigit():
        return None
    return parts[0], int(parts[1])


def remove_stale_partials(out: Path) -> None:
    """Staging folders of runs on this host that died without cleaning up (SIGKILL): their process is gone.

    Called with the folder's lock held, so no live run of a kalcal that locks is staging here. A pid
    says nothing about a process of another host (or a container with its own hostname) sharing the
    disk: those folders, and any whose name carries no host, are never removed.
    """
    root = Path(resolved(out))
    host = host_name()
    for entry in root.glob(PARTIAL_PREFIX + "*"):
        owner = _staging_owner(entry.name)
        if owner is None or owner[0] != host or owner[1] == os.getpid():
            continue
        if entry.is_dir() and not entry.is_symlink() and entry.parent == root and not _pid_alive(owner[1]):
            shutil.rmtree(entry, ignore_errors=True)


def make_staging(out: Path) -> tuple[Path, str]:
    """A new staging folder in ``out`` and the token of the marker written into it (:data:`STAGING_MARKER`)."""
    staging = Path(tempfile.mkdtemp(prefix=f"{PARTIAL_PREFIX}{host_name()}-{os.getpid()}-", dir=out))
    token = f"{host_name()} {os.getpid()} {secrets.token_hex(16)}"
    try:
        (staging / STAGING_MARKER).write_text(token + "\n", encoding="utf-8")
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return Path(resolved(staging)), token


def remove_staging(out: Path, staging: Path) -> None:
    """Remove a failed run's staging folder: only the real folder of that name directly in ``out``."""
    if staging.parent == Path(resolved(out)) and staging.name.startswith(PARTIAL_PREFIX) and not staging.is_symlink():
        shutil.rmtree(staging, ignore_errors=True)
