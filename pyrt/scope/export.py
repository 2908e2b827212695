"""Scope frames to CSV, .npz, MCAP, and plots as PNG, SVG or PDF (files written atomically)."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import numpy as np

from pyrt.errors import CommandError
from pyrt.fileio import atomic_write
from pyrt.scope.mcapfile import save_frame_mcap
from pyrt.scope.scope import Frame

__all__ = [
    "PLOT_SUFFIXES",
    "SAVE_SUFFIXES",
    "axis_label",
    "check_plot_path",
    "check_save_path",
    "column_title",
    "confine",
    "frame_figure",
    "is_hex",
    "plot_frame",
    "save_frame",
]

#: The file name endings ``scope save`` writes (the samples: a table, numpy
#: arrays, or MCAP, which needs the ``mcap`` library).
SAVE_SUFFIXES = (".csv", ".npz", ".mcap")
#: The file name endings ``scope plot`` writes, each in the format it names.
PLOT_SUFFIXES = (".png", ".svg", ".pdf")


def check_save_path(path: str | Path) -> Path:
    """``path`` as a :class:`Path` if :func:`save_frame` writes its format;
    CommandError naming the formats otherwise (nothing is written)."""
    path = Path(path)
    if path.suffix.lower() not in SAVE_SUFFIXES:
        raise CommandError(f"scope save: use a file name ending {_either(SAVE_SUFFIXES)}, "
                           f"got {path.name!r}")
    return path


def check_plot_path(path: str | Path) -> Path:
    """``path`` as a :class:`Path` if :func:`plot_frame` draws its format;
    CommandError naming the formats otherwise (nothing is written)."""
    path = Path(path)
    if path.suffix.lower() not in PLOT_SUFFIXES:
        got = (f"{path.name!r} has no extension" if not path.suffix
               else f"got {path.name!r}")
        raise CommandError(f"scope plot: the file name's extension names the format, one of "
                           f"{_either(PLOT_SUFFIXES)}; {got}")
    return path


def confine(name: str | Path, directory: str | Path | None, what: str) -> Path:
    """The file ``name`` inside ``directory`` (None: the working directory), or
    CommandError if it would land outside it: an absolute path elsewhere, a
    ``..`` that climbs out, a symbolic link that points out.  A relative name is
    taken relative to ``directory``.  ``what`` names the command in the message."""
    root = Path(directory if directory is not None else Path.cwd()).resolve()
    path = Path(name)
    target = (path if path.is_absolute() else root / path).resolve()
    if target == root or not target.is_relative_to(root):
        where = ("the directory --scope-dir names" if directory is not None
                 else "the working directory")
        raise CommandError(f"{what}: {str(name)[:80]!r} is outside {root}: the scope writes "
                           f"files only inside {where}; give a name inside it "
                           f"(nothing written)")
    return target


def _either(suffixes: tuple[str, ...]) -> str:
    return ", ".join(suffixes[:-1]) + " or " + suffixes[-1]


def save_frame(frame: Frame, path: str | Path) -> Path:
    """Write ``frame`` as CSV (``.csv``: a header naming the columns with their
    units, ``encoder [counts]``, time in seconds first) or numpy ``.npz``
    (arrays ``t_ns``, ``data``, ``channels``, ``units``), or MCAP (``.mcap``:
    a JSON channel per object, a message per sample; see
    :func:`~pyrt.scope.mcapfile.save_frame_mcap`)."""
    path = check_save_path(path)
    suffix = path.suffix.lower()
    if suffix == ".mcap":
        return save_frame_mcap(frame, path)
    if suffix == ".csv":
        text = io.StringIO()
        header = ",".join(["t_s", *(column_title(frame, k) for k in range(len(frame.channels)))])
        table = np.column_stack([frame.t_ns / 1e9, frame.data])
        np.savetxt(text, table, delimiter=",", header=header, comments="", fmt="%.9g")
        data = text.getvalue().encode("utf-8")
    elif suffix == ".npz":
        buf = io.BytesIO()
        np.savez(
            buf,
            t_ns=frame.t_ns,
            data=frame.data,
            channels=np.array(frame.channels),
            units=np.array([frame.unit(k) for k in range(len(frame.channels))]),
            trigger_index=np.array(-1 if frame.trigger_index is None else frame.trigger_index),
        )
        data = buf.getvalue()
    try:
        atomic_write(path, data)
    except OSError as exc:
        raise CommandError(f"scope save: cannot write {path}: {exc.strerror}") from None
    return path


def column_title(frame: Frame, k: int) -> str:
    """Channel ``k``'s CSV column: its name and units (``encoder [counts]``);
    the name alone when its units are not known."""
    unit = frame.unit(k)
    return f"{frame.channels[k]} [{unit}]" if unit else frame.channels[k]


def axis_label(frame: Frame, k: int) -> str:
    """The y-axis label of channel ``k``: its name and units, and ``hex``
    when the robot writes it in hexadecimal (the gripper's RAM)."""
    units = frame.unit(k) or "units not given"
    if is_hex(frame.format_of(k)):
        units += ", hex"
    return f"{frame.channels[k]} ({units})"


def is_hex(fmt: str) -> bool:
    """True for a format spec that writes an integer in hexadecimal (``02X``, ``x``)."""
    return fmt[-1:] in ("X", "x")


def plot_frame(frame: Frame, path: str | Path) -> Path:
    """Draw ``frame`` to ``path``, one trace per channel (needs matplotlib), in
    the format its extension names: PNG, SVG or PDF (:data:`PLOT_SUFFIXES`;
    any other extension, or none, is refused before anything is drawn).

    Time is loop time in seconds, as in the CSV (:func:`save_frame`); every y
    axis names its units; a channel the robot writes in hex (``fmt`` ``02X``)
    has hex tick labels."""
    path = check_plot_path(path)
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise CommandError(
            "scope plot needs matplotlib, which is not installed: pip install 'pyrt[plot]'"
        ) from None
    fig = frame_figure(frame)
    buf = io.BytesIO()
    fig.savefig(buf, format=path.suffix.lower()[1:], dpi=100)
    plt.close(fig)
    try:
        atomic_write(path, buf.getvalue())
    except OSError as exc:
        raise CommandError(f"scope plot: cannot write {path}: {exc.strerror}") from None
    return path


def frame_figure(frame: Frame) -> Any:
    """The matplotlib figure :func:`plot_frame` draws (matplotlib must be there)."""
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, MaxNLocator

    t = frame.t_ns / 1e9  # the CSV's t_s column: the two agree
    n = len(frame.channels)
    fig, axes = plt.subplots(n, 1, figsize=(9, 1.8 + 1.6 * n), sharex=True, squeeze=False)
    for k in range(n):
        ax = axes[k][0]
        ax.plot(t, frame.data[:, k], lw=1)
        ax.set_ylabel(axis_label(frame, k))
        fmt = frame.format_of(k)
        if is_hex(fmt):
            ax.yaxis.set_major_locator(MaxNLocator(integer=True))
            ax.yaxis.set_major_formatter(
                FuncFormatter(lambda v, _pos, f=fmt: format(round(v), f)))
        if frame.trigger_index is not None and frame.t_ns.size:
            ax.axvline(t[frame.trigger_index], color="r", lw=0.8, ls="--")
    axes[-1][0].set_xlabel("loop time (s)")
    axes[-1][0].ticklabel_format(axis="x", useOffset=False, style="plain")
    fig.suptitle(f"pyrt scope ({frame.mode}, {frame.t_ns.size} samples)")
    fig.tight_layout()
    return fig
