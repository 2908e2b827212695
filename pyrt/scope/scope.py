"""The software oscilloscope (004): time-stamped real-time data for tuning.

Channels are sampled in the loop every ``every`` ticks into a preallocated
numpy ring buffer.  Modes, as on a bench scope:

* ``normal``: wait for the trigger, capture a frame (``pre`` of it before the
  trigger point), keep the frame for read-out, re-arm;
* ``single``: the same, once, then stop;
* ``auto``: like normal, but a frame is captured anyway when no trigger
  comes within one frame length;
* ``roll``: no trigger; the read-out is always the latest ``capacity``
  samples, oldest first (what halscope never had).

The per-sample path is one compiled getter call and two appends to staging
arrays; every 64 samples the stage is copied into the ring and the trigger
is searched with numpy, so sampling 8 channels costs well under a
microsecond per tick.  :meth:`Scope.sample` runs in the loop thread; every
other method is for the application, through the runner's mailbox.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from pyrt.errors import CommandError
from pyrt.scope.sources import Source, compile_sampler, compile_sources

__all__ = ["Frame", "Scope", "Trigger"]

_STAGE = 64
MODES = ("normal", "single", "auto", "roll")


@dataclass(frozen=True)
class Trigger:
    """Trigger on ``channel`` crossing ``level`` (rising or falling); ``pre`` is
    the fraction of the frame kept from before the trigger point."""

    channel: str
    level: float
    edge: str = "rising"
    pre: float = 0.1

    def __post_init__(self) -> None:
        if self.edge not in ("rising", "falling"):
            raise CommandError(f"trigger edge must be 'rising' or 'falling', got {self.edge!r}")
        if not 0.0 <= self.pre < 1.0:
            raise CommandError(f"pre-trigger fraction must be 0 <= pre < 1, got {self.pre!r}")
        if self.level != self.level:
            raise CommandError("trigger level must be a number, not NaN")


@dataclass(frozen=True)
class Frame:
    """A captured frame: times (ns, loop clock), values (samples x channels)."""

    t_ns: np.ndarray
    data: np.ndarray
    channels: tuple[str, ...]
    #: Sample index of the trigger point within the frame; None for roll/auto-forced.
    trigger_index: int | None
    mode: str
    #: Each channel's units and format spec (see :class:`Source`); "" where not known.
    units: tuple[str, ...] = ()
    formats: tuple[str, ...] = ()

    def unit(self, k: int) -> str:
        """Channel ``k``'s units ("" when not known)."""
        return self.units[k] if k < len(self.units) else ""

    def format_of(self, k: int) -> str:
        """Channel ``k``'s format spec ("" when not known)."""
        return self.formats[k] if k < len(self.formats) else ""

    def column(self, name: str) -> np.ndarray:
        """The samples of one channel."""
        try:
            return self.data[:, self.channels.index(name)]
        except ValueError:
            raise CommandError(f"no channel {name!r} in this frame") from None


class Scope:
    """A software oscilloscope of up to ``max_channels`` channels and
    ``capacity`` samples per channel, sampling every ``every`` ticks."""

    def __init__(self, capacity: int = 16_000, max_channels: int = 16, every: int = 1):
        if capacity < 2:
            raise ValueError(f"scope capacity must be >= 2 samples, got {capacity}")
        if not 1 <= max_channels <= 64:
            raise ValueError(f"max_channels must be 1..64, got {max_channels}")
        self.capacity = capacity
        self.max_channels = max_channels
        self._every = 1
        self.every = every
        self._names: list[str] = []
        self._sources: list[Source] = []
        self.error: str | None = None
        self.trigger: Trigger | None = None
        # auto: a frame per trigger, or per frame length when none comes (the
        # mode that shows something without setting up a trigger first)
        self.mode = "auto"
        self.state = "stopped"
        self._frame: Frame | None = None
        self.frames = 0
        self._reset_buffers()

    # -- configuration (application side, with the scope stopped or not) -----

    @property
    def every(self) -> int:
        """Sample every N-th tick."""
        return self._every

    @every.setter
    def every(self, n: int) -> None:
        if not isinstance(n, int) or not 1 <= n <= 1_000_000:
            raise CommandError(f"sample interval must be 1..1000000 ticks, got {n!r}")
        self._every = n
        self._countdown = n

    @property
    def channels(self) -> list[str]:
        """Channel names in column order."""
        return list(self._names)

    def add(self, name: str, source: Source) -> None:
        """Add a channel; capture restarts (the buffer's columns change)."""
        if name in self._names:
            raise CommandError(f"channel {name!r} is already on the scope")
        if len(self._names) >= self.max_channels:
            raise CommandError(f"the scope has {self.max_channels} channels already")
        getter = compile_sources([*self._sources, source])
        try:
            values = getter()
            [float(v) for v in values]
        except (TypeError, ValueError, ArithmeticError) as exc:
            raise CommandError(f"channel {name!r} does not read as a number: {exc}") from None
        self._names.append(name)
        self._sources.append(source)
        self._restart()

    def remove(self, name: str) -> None:
        """Remove a channel (and a trigger on it); capture restarts."""
        if name not in self._names:
            raise CommandError(f"no channel {name!r} on the scope")
        i = self._names.index(name)
        del self._names[i]
        del self._sources[i]
        if self.trigger is not None and self.trigger.channel == name:
            self.trigger = None
        self._restart()

    def set_trigger(
        self, channel: str, level: float, edge: str = "rising", pre: float = 0.1
    ) -> None:
        """Trigger on ``channel`` crossing ``level``."""
        if channel not in self._names:
            raise CommandError(f"no channel {channel!r} on the scope: add it first")
        self.trigger = Trigger(channel, float(level), edge, float(pre))
        self._restart()

    def clear_trigger(self) -> None:
        """No trigger: normal/single wait forever; auto captures a frame per frame length."""
        self.trigger = None
        self._restart()

    # -- running ---------------------------------------------------------------

    def run(self, mode: str | None = None) -> None:
        """Start acquiring in ``mode`` (default: the current mode)."""
        if mode is not None:
            if mode not in MODES:
                raise CommandError(f"scope mode must be one of {', '.join(MODES)}, got {mode!r}")
            self.mode = mode
        if not self._names:
            raise CommandError("the scope has no channels: 'scope add CHANNEL' first")
        if self.mode in ("normal", "single") and self.trigger is None:
            raise CommandError(f"{self.mode} mode needs a trigger: 'scope trigger CH LEVEL'")
        self._reset_buffers()
        self.error = None
        self.state = "rolling" if self.mode == "roll" else "armed"

    def single(self) -> None:
        """Arm for one triggered frame."""
        self.run("single")

    def stop(self) -> None:
        """Stop acquiring; what was captured stays readable.  Stopped before
        the first frame filled, the samples taken so far become the frame
        (the trigger's, if one was seen), so a stop never loses what was seen."""
        self._flush()
        if self._frame is None and self.state in ("armed", "triggered"):
            if self.state == "triggered" and self._trig_g is not None:
                pre = round(self.trigger.pre * self.capacity) if self.trigger else 0
                first = max(self._trig_g - pre, self._g - self.capacity, 0)
                self._complete(first, self._trig_g - first, self._g - first)
            else:
                first = max(self._arm_g, self._g - self.capacity)
                if self._g > first:
                    self._complete(first, None, self._g - first)
        self.state = "stopped"

    def _restart(self) -> None:
        running = self.state not in ("stopped", "done")
        self._reset_buffers()
        self._frame = None
        if running:
            self.state = "rolling" if self.mode == "roll" else "armed"

    def _reset_buffers(self) -> None:
        n = max(1, len(self._names))
        size = self.capacity + _STAGE
        self._ring = np.zeros((size, n), dtype=np.float64)
        self._ring_t = np.zeros(size, dtype=np.int64)
        self._g = 0  # samples taken since the buffers were reset
        nch = len(self._sources)
        packer = struct.Struct("<q" + "d" * nch)
        self._row = packer.size
        self._dtype = np.dtype([("t", "<i8"), ("v", "<f8", (nch,))])
        self._stage = bytearray(packer.size * _STAGE)
        self._sampler = compile_sampler(self._sources, packer.pack_into)
        self._staged = 0
        self._arm_g = 0
        self._trig_g: int | None = None
        self._prev: float | None = None
        self._countdown = self._every

    # -- the loop side -------------------------------------------------------

    @property
    def state(self) -> str:
        """stopped, armed, triggered, done (single frame captured) or rolling."""
        return self._state

    @state.setter
    def state(self, value: str) -> None:
        self._state = value
        self._acquiring = value not in ("stopped", "done")

    def sample(self, now_ns: int) -> None:
        """Loop handler: take a sample every ``every`` ticks while acquiring."""
        if not self._acquiring:
            return
        self._countdown -= 1
        if self._countdown:
            return
        self._countdown = self._every
        try:
            self._sampler(self._stage, self._staged * self._row, now_ns)
        except Exception as exc:  # a channel stopped reading as a number
            self.error = f"sampling stopped: {type(exc).__name__}: {exc}"
            self.state = "stopped"
            return
        self._staged += 1
        if self._staged >= _STAGE:
            self._flush()

    def _flush(self) -> None:
        n = self._staged
        if not n:
            return
        nch = len(self._names)
        rec = np.frombuffer(self._stage, dtype=self._dtype, count=n)
        block = rec["v"].reshape(n, nch)
        tblock = rec["t"]
        size = self._ring.shape[0]
        g0 = self._g
        start = g0 % size
        first = min(n, size - start)  # the stage never exceeds the ring's margin
        self._ring[start : start + first, :nch] = block[:first]
        self._ring_t[start : start + first] = tblock[:first]
        if first < n:
            self._ring[: n - first, :nch] = block[first:]
            self._ring_t[: n - first] = tblock[first:]
        self._g = g0 + n
        if self.state in ("armed", "triggered"):
            self._scan(block, g0)
        self._staged = 0

    def _scan(self, block: np.ndarray, g0: int) -> None:
        """Find triggers in a freshly flushed block; complete frames."""
        cap = self.capacity
        trig = self.trigger
        pre = round(trig.pre * cap) if trig is not None else 0
        post = cap - pre
        col = block[:, self._names.index(trig.channel)] if trig is not None else None
        j = 0
        n = block.shape[0]
        while True:
            if self.state == "armed":
                start = max(j, self._arm_g + pre - g0)
                hit = self._find_edge(col, start, trig) if col is not None else None
                if hit is not None:
                    self._trig_g = g0 + hit
                    self.state = "triggered"
                elif self.mode == "auto" and self._g - self._arm_g >= cap:
                    self._complete(self._g - cap, None)
                    self._arm_g = self._g
                    break
                else:
                    break
            if self.state == "triggered":
                end = self._trig_g + post
                if self._g < end:
                    break
                self._complete(self._trig_g - pre, pre)
                if self.mode == "single":
                    self.state = "done"
                    break
                self._arm_g = end
                self.state = "armed"
                j = end - g0
                if j >= n:
                    break
        if col is not None and n:
            self._prev = float(col[-1])

    def _find_edge(self, col: np.ndarray, start: int, trig: Trigger) -> int | None:
        n = col.shape[0]
        if start >= n:
            return None
        start = max(start, 0)
        prev = np.empty(n - start)
        prev[1:] = col[start:-1]
        if start > 0:
            prev[0] = col[start - 1]
        else:
            prev[0] = self._prev if self._prev is not None else np.nan
        cur = col[start:]
        if trig.edge == "rising":
            hits = np.flatnonzero((prev < trig.level) & (cur >= trig.level))
        else:
            hits = np.flatnonzero((prev > trig.level) & (cur <= trig.level))
        return int(hits[0]) + start if hits.size else None

    def _complete(self, first_g: int, trigger_index: int | None,
                  count: int | None = None) -> None:
        size = self._ring.shape[0]
        pos = (first_g + np.arange(self.capacity if count is None else count)) % size
        nch = len(self._names)
        self._frame = Frame(
            t_ns=self._ring_t[pos].copy(),
            data=self._ring[pos, :nch].copy(),
            channels=tuple(self._names),
            trigger_index=trigger_index,
            mode=self.mode,
            units=tuple(src.units for src in self._sources),
            formats=tuple(src.fmt for src in self._sources),
        )
        self.frames += 1

    # -- read-out (application side) -----------------------------------------

    def read(self) -> Frame | None:
        """The latest frame (roll mode: the latest samples), or None if none yet."""
        self._flush()
        if self.mode == "roll":
            n = min(self._g, self.capacity)
            if n == 0:
                return None
            size = self._ring.shape[0]
            pos = (self._g - n + np.arange(n)) % size
            nch = len(self._names)
            return Frame(
                self._ring_t[pos].copy(), self._ring[pos, :nch].copy(),
                tuple(self._names), None, "roll",
                units=tuple(src.units for src in self._sources),
                formats=tuple(src.fmt for src in self._sources),
            )
        return self._frame

    def status(self) -> str:
        """One line: mode, state, channels, trigger, frames captured."""
        trig = "none"
        if self.trigger is not None:
            t = self.trigger
            trig = f"{t.channel} {t.edge} {t.level:g} pre {t.pre:g}"
        line = (
            f"scope {self.state} ({self.mode}), every {self.every} tick(s), "
            f"{self.capacity} samples, channels: {', '.join(self._names) or '-'}; "
            f"trigger: {trig}; frames: {self.frames}"
        )
        return line + (f"; {self.error}" if self.error else "")
