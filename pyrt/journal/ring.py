"""The black box: the last seconds of a journal, in memory, within a byte budget."""

from __future__ import annotations

import contextlib
import os
from collections import deque
from typing import BinaryIO

from pyrt.journal.format import END, KIND_END, KIND_HEADER, JournalError, frame

__all__ = ["DEFAULT_BUDGET", "DEFAULT_SECONDS", "FRAME_OVERHEAD", "BlackBox"]

#: What a black box keeps by default: this many seconds ...
DEFAULT_SECONDS = 10.0
#: ... within this many bytes (8 MiB).
DEFAULT_BUDGET = 8 << 20
#: Bytes counted against the budget for each frame kept, beside its own bytes
#: (the Python objects that hold it).
FRAME_OVERHEAD = 192


class BlackBox:
    """The journal's frames of the last ``seconds`` of clock time, at most
    ``budget_bytes`` bytes in all (each frame counted as its size plus
    :data:`FRAME_OVERHEAD`), the oldest dropped first.

    Every tick frame begins with a keyframe, so whatever the ring still holds
    is readable on its own: :meth:`dump` writes a journal file of it (a header,
    the frames, an end frame).  A :class:`~pyrt.journal.Journal` feeds it from
    its writer thread; use it through the journal (:meth:`Journal.dump_black_box`)
    while one runs.
    """

    def __init__(self, seconds: float = DEFAULT_SECONDS, budget_bytes: int = DEFAULT_BUDGET):
        if not isinstance(seconds, int | float) or isinstance(seconds, bool) or not seconds > 0:
            raise JournalError(f"black box: seconds must be positive, got {seconds!r}")
        if isinstance(budget_bytes, bool) or not isinstance(budget_bytes, int) \
                or budget_bytes < 4096:
            raise JournalError(f"black box: budget_bytes must be an integer >= 4096, "
                               f"got {budget_bytes!r}")
        self.seconds = float(seconds)
        self.budget_bytes = budget_bytes
        self._span_ns = int(seconds * 1e9)
        #: (frame bytes, first time ns, last time ns, ticks)
        self._frames: deque[tuple[bytes, int, int, int]] = deque()
        self.nbytes = 0
        #: Frames dropped so far (to keep the budget or the span).
        self.dropped = 0

    def add(self, data: bytes, first_time_ns: int, last_time_ns: int, ticks: int = 0) -> None:
        """Keep one frame (times: its first and last tick's; a gap frame: the last tick's)."""
        frames = self._frames
        frames.append((data, first_time_ns, last_time_ns, ticks))
        self.nbytes += len(data) + FRAME_OVERHEAD
        limit = last_time_ns - self._span_ns
        while frames and (self.nbytes > self.budget_bytes
                          or (len(frames) > 1 and frames[1][1] <= limit)):
            old = frames.popleft()
            self.nbytes -= len(old[0]) + FRAME_OVERHEAD
            self.dropped += 1

    @property
    def frames(self) -> int:
        """Frames kept."""
        return len(self._frames)

    @property
    def ticks(self) -> int:
        """Tick records kept."""
        return sum(f[3] for f in self._frames)

    @property
    def span_ns(self) -> int:
        """Clock time from the first tick kept to the last."""
        if not self._frames:
            return 0
        return self._frames[-1][2] - self._frames[0][1]

    def clear(self) -> None:
        """Drop everything kept."""
        self._frames.clear()
        self.nbytes = 0

    def dump(self, target: str | os.PathLike[str] | BinaryIO, header: bytes) -> int:
        """Write what the ring holds as a journal file (``header``: an ``H`` frame's
        payload) to a path (atomically: a temporary file renamed) or an open binary
        stream; return the number of tick records written."""
        frames = list(self._frames)
        ticks = sum(f[3] for f in frames)
        parts = [frame(KIND_HEADER, header), *(f[0] for f in frames),
                 frame(KIND_END, END.pack(ticks, 0))]
        if isinstance(target, str | os.PathLike):
            path = os.fspath(target)
            tmp = f"{path}.tmp{os.getpid()}"
            try:
                with open(tmp, "wb") as fh:
                    for p in parts:
                        fh.write(p)
                    fh.flush()
                    os.fsync(fh.fileno())
                os.replace(tmp, path)
            except OSError as exc:
                with contextlib.suppress(OSError):
                    os.unlink(tmp)
                raise JournalError(f"black box {path}: {exc.strerror or exc}") from None
        else:
            for p in parts:
                target.write(p)
            target.flush()
        return ticks
