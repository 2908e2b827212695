"""Atomic file replacement: a crash at any moment leaves the old file or the new one.

Used by every writer of files a user relies on: the object databases, scope
exports, logs written as a whole.  :func:`disk_error` turns the system's
``OSError`` of a failed write into the one :class:`~pyrt.errors.DiskError`
every writer reports (the file and the system's reason, one sentence).
"""

from __future__ import annotations

import contextlib
import errno
import os
import tempfile
from pathlib import Path

from pyrt.errors import DiskError

__all__ = ["FULL", "atomic_write", "disk_error", "restate"]

#: The system's errors that mean the disk (or the user's quota) is full.
FULL = frozenset({errno.ENOSPC, getattr(errno, "EDQUOT", errno.ENOSPC)})


def disk_error(what: str, path: str | os.PathLike[str] | None, exc: OSError) -> DiskError:
    """The DiskError of ``what`` (``"database write-back"``) failing on ``path``:
    ``"database write-back failed: cannot write /db/AXIS.dat: No space left on
    device (the disk is full)"`` (without ``what``: from ``"cannot write"`` on)."""
    where = os.fspath(path) if path is not None else (exc.filename or None)
    reason = exc.strerror or str(exc) or type(exc).__name__
    if exc.errno in FULL:
        reason += " (the disk is full)"
    target = f"cannot write {where}: " if where else ""
    return DiskError(f"{what} failed: {target}{reason}" if what else f"{target}{reason}",
                     None if where is None else str(where), exc.errno)


def atomic_write(path: Path, data: bytes) -> None:
    """Replace ``path`` by ``data``: temp file in the same directory, write,
    flush, fsync, rename over ``path``, fsync the directory.

    The temp file takes the original's permission bits.  On any error the
    temp file is removed and ``path`` is untouched.
    """
    path = Path(path)
    directory = path.parent
    try:
        mode = os.stat(path).st_mode & 0o7777
    except FileNotFoundError:
        mode = 0o644
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=directory)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fchmod(f.fileno(), mode)
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    dfd = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(dfd)
    finally:
        os.close(dfd)


def restate(what: str, exc: DiskError) -> DiskError:
    """``exc`` said as ``what``'s failure (``"pattern log failed: cannot write ..."``)."""
    return DiskError(f"{what} failed: {exc.message}", exc.path, exc.errno)
