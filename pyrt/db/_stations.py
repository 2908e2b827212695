"""The stations packaged with pyrt, and copying one into a working directory.

Write-back edits files in place, so a run never points it at the installed
package: :func:`copy_station` copies a packaged station's ``.dat`` files to
a working directory first.
"""

from __future__ import annotations

import os
import shutil
from importlib import resources
from pathlib import Path

import platformdirs

from pyrt.db._schema import FILES
from pyrt.errors import ConfigError
from pyrt.fileio import atomic_write, disk_error

__all__ = ["STATIONS", "copy_station", "station_directory"]

#: The packaged stations.
STATIONS = ("prototype", "sno")


def station_directory(name: str) -> Path:
    """The installed directory of packaged station ``name`` (read-only use)."""
    key = name.lower()
    if key not in STATIONS:
        raise ConfigError(f"no packaged station {name!r}; expected one of {', '.join(STATIONS)}")
    root = resources.files("pyrt.db") / "stations" / key
    if not isinstance(root, os.PathLike):  # pyrt imported from a zip archive
        raise ConfigError(f"packaged station {name!r} is not a directory ({root!r}): "
                          "install pyrt as files (pip install, not a zip archive)")
    return Path(os.fspath(root))


def default_working_directory(name: str) -> Path:
    """Where a run keeps its working copy of packaged station ``name``.

    ``$PYRT_HOME/stations/<name>`` if ``PYRT_HOME`` is set, else
    ``stations/<name>`` in pyrt's user state directory as the platform
    defines it (platformdirs: ``$XDG_STATE_HOME/pyrt``, by default
    ``~/.local/state/pyrt``, on Linux; ``~/Library/Application Support/pyrt``
    on macOS; ``%LOCALAPPDATA%\\pyrt`` on Windows).  Nothing is created here.
    """
    key = name.lower()
    if key not in STATIONS:
        raise ConfigError(f"no packaged station {name!r}; expected one of {', '.join(STATIONS)}")
    home = os.environ.get("PYRT_HOME")
    if home:
        return Path(home) / "stations" / key
    return Path(platformdirs.user_state_dir("pyrt", appauthor=False)) / "stations" / key


def copy_station(name: str, dest_dir: str | os.PathLike[str], *, overwrite: bool = False) -> Path:
    """Copy packaged station ``name``'s database files into ``dest_dir``.

    ``dest_dir`` is created if needed.  Existing database files there are
    kept (a working copy carries the last written positions) unless
    ``overwrite``; returns ``dest_dir``.  Each file is written atomically.
    """
    src = station_directory(name)
    dest = Path(dest_dir)
    try:
        dest.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"cannot make the station directory: {exc.strerror or exc}",
                          str(dest)) from None
    if dest.resolve() == src.resolve():
        raise ConfigError("refusing to copy a packaged station onto itself", str(dest))
    for filename in FILES.values():
        target = dest / filename
        if target.exists() and not overwrite:
            continue
        try:
            atomic_write(target, (src / filename).read_bytes())
            shutil.copymode(src / filename, target)
        except OSError as exc:  # a full disk: a sentence, not a traceback
            raise ConfigError(f"cannot copy the packaged {name.lower()} station here: "
                              f"{disk_error('', target, exc).message}", str(dest)) from None
    return dest
