"""One process per station directory: an exclusive lock on ``--db DIR``.

Two processes writing back into one directory would clobber each other's
LENGTH, ZEROLENGTH and POSITION.  :func:`lock_directory` takes an exclusive,
non-blocking ``flock`` on ``DIR/.pyrt.lock`` and writes the holder's pid
into it; a second process (or a second station in the same process) gets a
:class:`~pyrt.errors.ConfigError` naming the holder's pid.  The lock goes
with the process (the kernel drops it on exit, even after a crash); the
file stays.  Writing the pid is start-up's first write: a full disk refuses
the start there, with a sentence, before anything moves.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
from pathlib import Path

from pyrt.errors import ConfigError
from pyrt.fileio import FULL

__all__ = ["LOCK_FILE", "DirectoryLock", "lock_directory"]

#: The lock file in a station directory.
LOCK_FILE = ".pyrt.lock"


class DirectoryLock:
    """A held lock on a station directory (:meth:`release` lets it go; twice is harmless)."""

    def __init__(self, directory: Path, fd: int | None):
        self.directory = directory
        self._fd: int | None = fd

    @property
    def held(self) -> bool:
        return self._fd is not None

    def release(self) -> None:
        fd, self._fd = self._fd, None
        if fd is not None:
            try:
                os.ftruncate(fd, 0)
                fcntl.flock(fd, fcntl.LOCK_UN)
            finally:
                os.close(fd)


def lock_directory(directory: str | os.PathLike[str]) -> DirectoryLock:
    """Lock station directory ``directory`` for this process (ConfigError if another holds it)."""
    d = Path(directory)
    path = d / LOCK_FILE
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0), 0o644)
    except OSError as exc:
        raise ConfigError(f"cannot lock the station directory: {exc.strerror}", str(path)) from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        try:
            holder = os.pread(fd, 32, 0).decode("ascii", "replace").strip() or "unknown"
        finally:
            os.close(fd)
        raise ConfigError(f"station directory {str(d)!r} is in use by process {holder} "
                          f"(lock {LOCK_FILE}); stop that one first or give another --db",
                          None) from None
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode("ascii"), 0)
    except OSError as exc:  # a full disk: refused at start-up, not a fault later
        lock = DirectoryLock(d, fd)
        with contextlib.suppress(OSError):
            lock.release()
        raise ConfigError(f"cannot start on the station directory: writing {LOCK_FILE} "
                          f"failed: {_reason(exc)}; write-back could not keep the databases "
                          "either: free some space (or give another --db) first",
                          str(d)) from None
    return DirectoryLock(d, fd)


def _reason(exc: OSError) -> str:
    full = exc.errno in FULL
    return (exc.strerror or str(exc)) + (" (the disk is full)" if full else "")
