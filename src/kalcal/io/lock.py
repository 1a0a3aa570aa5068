"""One run at a time per output folder: an exclusive ``flock`` on ``OUT/.kalcal-lock``.

The lock is taken before a run reads the folder's manifest and released after its commit (or after
its staging folder is removed, when it fails), so that two runs whose lifetimes overlap cannot both
commit into the folder. It is not waited for: a second run stops at once, naming the host and the
process that hold it (written into the lock file by the holder).

A lock held by a process that dies (SIGKILL, power loss) is released by the kernel; the file it
leaves is taken over by the next run. The holder removes the file before releasing the lock, and a
run that gets the lock checks that the file it locked is still the one at the path (else another run
removed it in between, and it tries again), so that two runs never hold locks on two different files.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import socket
import time
from pathlib import Path

from kalcal.io.manifest import OutputError

__all__ = ["LOCK", "FolderLock", "host_name"]

LOCK = ".kalcal-lock"

# how long a refused run waits for the holder's host and pid to appear in the file (the holder writes
# them right after it gets the lock): long enough for a busy machine, short for a message
_HOLDER_WAIT_S = 1.0


def host_name() -> str:
    """This machine's name (``socket.gethostname()``), in characters safe in a file name (others ``_``)."""
    name = socket.gethostname() or "unknown-host"
    return "".join(c if c.isalnum() or c in ".-" else "_" for c in name)


def _holder(path: Path) -> str:
    deadline = time.monotonic() + _HOLDER_WAIT_S
    while True:
        try:
            text = path.read_text(encoding="utf-8", errors="replace").split()
        except OSError:
            text = []
        if len(text) >= 2:
            return f"host {text[0]}, pid {text[1]}"
        if time.monotonic() >= deadline:
            return "host and pid not recorded"
        time.sleep(0.02)


class FolderLock:
    """The exclusive lock on ``folder/.kalcal-lock``, held from :meth:`acquire` to :meth:`release`.

    Parameters
    ----------
    folder : Path
        The output folder (it exists).
    where : str
        How messages name the folder (``--out DIR``).
    other : str
        What a refused run is told to do instead (``choose another --out``).
    """

    def __init__(self, folder: Path, where: str, other: str) -> None:
        self.path = Path(folder) / LOCK
        self.where = where
        self.other = other
        self._fd: int | None = None

    def acquire(self) -> None:
        """Take the lock, or raise :class:`OutputError` naming the holder (or why the folder cannot be locked)."""
        while True:
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC | os.O_NOFOLLOW, 0o644)
            except OSError as exc:
                raise OutputError(f"{self.where}: cannot lock the folder ({exc.strerror or exc}: {self.path})") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                os.close(fd)
                if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    raise OutputError(
                        f"{self.where}: another kalcal run is writing into this folder ({_holder(self.path)}, "
                        f"{LOCK}); wait for it to end or {self.other}"
                    ) from None
                with contextlib.suppress(OSError):
                    if os.stat(self.path, follow_symlinks=False).st_size == 0:
                        os.unlink(self.path)  # the empty file this run made: a failed first run leaves no folder
                raise OutputError(
                    f"{self.where}: cannot lock the folder ({exc.strerror or exc}: {self.path}); the file system "
                    f"does not support flock, so two runs into it could mix their files: {self.other}"
                ) from None
            try:
                now = os.stat(self.path, follow_symlinks=False)
            except FileNotFoundError:
                now = None
            mine = os.fstat(fd)
            if now is not None and (now.st_dev, now.st_ino) == (mine.st_dev, mine.st_ino):
                break
            os.close(fd)  # the holder before us removed the file after we opened it: lock the new one
        self._fd = fd
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{host_name()} {os.getpid()}\n".encode(), 0)

    def release(self) -> None:
        """Remove the lock file and release the lock (explicitly: a forked child may share the descriptor)."""
        if self._fd is None:
            return
        fd, self._fd = self._fd, None
        try:
            os.unlink(self.path)
        except OSError:
            pass
        try:
            fcntl.flock(fd, fcntl.LOCK_UN)
        finally:
            os.close(fd)
