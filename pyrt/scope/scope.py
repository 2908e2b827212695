"""The software oscilloscope (004): time-stamped real-time data for tuning.

Channels are sampled in the loop every ``every`` ticks into a preallocated
numpy ring buffer.  Modes, as on a bench scope:

* ``normal``: wait for the trigger, capture a frame (``pre`` of it before the
  trigger point), keep the frame for read-out, re-arm;
* ``single``: the same, once, then stop;
* ``auto``: like normal, but a frame is captured anyway when no trigger
  comes within one frame length; without a trigger it shows the latest
  samples as they come, as roll does;
* ``roll``: no trigger; the read-out is always the latest ``capacity``
  samples, oldest first (what halscope never had).

As on halscope, a triggered mode first fills the pre-trigger part of the
frame (``pre`` of ``capacity`` samples) and arms the trigger only when it
is full: :meth:`Scope.pre_fill` says how full it is, and a trigger event
that comes during the fill is not taken but counted and kept
(:attr:`Scope.missed`, :meth:`Scope.waiting`), so a scope never misses an
event silently.  The record length (``capacity``) is set with
:meth:`Scope.set_length`, within :data:`MAX_BUFFER_BYTES` of buffer.

The per-sample path is one compiled getter call and two appends to staging
arrays; every 64 samples the stage is copied into the ring and the trigger
is searched with numpy, so sampling 8 channels costs well under a
microsecond per tick.  :meth:`Scope.sample` runs in the loop thread; every
other method is for the application, through the runner's mailbox.
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from pyrt.errors import CommandError
from pyrt.scheduler import Loop
from pyrt.scope.report import ScopeReport
from pyrt.scope.sources import Source, compile_sampler, compile_sources
from pyrt.scope.stream import Layout, Sink, UdpStream

__all__ = ["MAX_BUFFER_BYTES", "MAX_LENGTH", "Frame", "Scope", "Trigger"]

log = logging.getLogger("pyrt.scope")

_STAGE = 64
_NEVER = 2**63  # the next stream time when nothing streams: one comparison a sample
MODES = ("normal", "single", "auto", "roll")
#: The longest record length, samples per channel.
MAX_LENGTH = 1_000_000
#: The most memory the sample buffer may take: (length + 64) x (channels + 1) x 8 bytes.
MAX_BUFFER_BYTES = 64 * 2**20


def buffer_bytes(length: int, channels: int) -> int:
    """The bytes of the sample buffer of ``length`` samples of ``channels`` channels."""
    return (length + _STAGE) * (max(1, channels) + 1) * 8


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


class Scope(ScopeReport):
    """A software oscilloscope of up to ``max_channels`` channels and
    ``capacity`` samples per channel, sampling every ``every`` ticks."""

    def __init__(self, capacity: int = 16_000, max_channels: int = 16, every: int = 1):
        if not 2 <= capacity <= MAX_LENGTH:
            raise ValueError(f"scope capacity must be 2..{MAX_LENGTH} samples, got {capacity}")
        if not 1 <= max_channels <= 64:
            raise ValueError(f"max_channels must be 1..64, got {max_channels}")
        self.capacity = capacity
        self.max_channels = max_channels
        # Switches the loop's sampling handler on and off (attach_to), or None.
        self._switch: Callable[[bool], None] | None = None
        self._acquiring = False
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
        #: Trigger events that came while the pre-trigger part filled (not taken),
        #: since the scope was last armed; :attr:`missed_t_ns` is the latest one's time.
        self.missed = 0
        self.missed_t_ns: int | None = None
        #: Loop time between two samples, ns (measured once samples were taken).
        self.sample_ns: int | None = None
        #: The loop's tick, ns, when whoever runs the scope says it (for times
        #: before a sample was taken).
        self.tick_ns: int | None = None
        #: The directory ``scope save`` and ``scope plot`` write into (and
        #: nowhere else); None: the working directory.
        self.directory: str | None = None
        #: The live stream of the samples (``scope stream``), or None.
        self.stream: UdpStream | None = None
        #: The Foxglove live server of the samples (``scope foxglove``), or None.
        self.foxglove: Sink | None = None
        #: The sinks that take samples, each with the loop time its next is due.
        self._sinks: list[list] = []
        self._stream_next = _NEVER
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

    def set_length(self, n: int) -> None:
        """Set the record length (samples per channel); capture restarts.  At most
        :data:`MAX_LENGTH`, and the buffer within :data:`MAX_BUFFER_BYTES`."""
        if isinstance(n, bool) or not isinstance(n, int) or not 2 <= n <= MAX_LENGTH:
            raise CommandError(f"record length must be 2..{MAX_LENGTH} samples, got {n!r}")
        self._check_memory(n, len(self._names))
        self.capacity = n
        self._restart()

    def _check_memory(self, length: int, channels: int) -> None:
        need = buffer_bytes(length, channels)
        if need > MAX_BUFFER_BYTES:
            most = MAX_BUFFER_BYTES // ((max(1, channels) + 1) * 8) - _STAGE
            raise CommandError(
                f"{length} samples of {channels} channel(s) need {need / 2**20:.1f} MiB of "
                f"buffer, more than the scope's {MAX_BUFFER_BYTES // 2**20} MiB: at most "
                f"{most} samples with {channels} channel(s)")

    def add(self, name: str, source: Source) -> None:
        """Add a channel; capture restarts (the buffer's columns change)."""
        if name in self._names:
            raise CommandError(f"channel {name!r} is already on the scope")
        if len(self._names) >= self.max_channels:
            raise CommandError(f"the scope has {self.max_channels} channels already")
        self._check_memory(self.capacity, len(self._names) + 1)
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
        (the trigger's, if one was seen), so a stop never loses what was seen.
        In auto mode without a trigger the latest samples, what :meth:`read`
        showed, become the frame."""
        self._flush()
        if self.mode == "auto" and self.trigger is None and self._acquiring:
            # what was shown (the latest samples) is what is kept
            if self._frame is None or self._g > self._arm_g:
                first = max(0, self._g - self.capacity)
                if self._g > first:
                    self._complete(first, None, self._g - first)
        elif self._frame is None and self.state in ("armed", "triggered"):
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
        self._layout = Layout(packer, tuple(self._names))
        self._staged = 0
        self._arm_g = 0
        self._trig_g: int | None = None
        self._prev: float | None = None
        self._countdown = self._every
        self.missed = 0
        self.missed_t_ns = None

    # -- the loop side -------------------------------------------------------

    @property
    def state(self) -> str:
        """stopped, armed, triggered, done (single frame captured) or rolling."""
        return self._state

    @state.setter
    def state(self, value: str) -> None:
        self._state = value
        acquiring = value not in ("stopped", "done")
        if acquiring != self._acquiring and self._switch is not None:
            self._switch(acquiring)
        self._acquiring = acquiring

    def attach_to(self, loop: Loop, name: str = "scope") -> None:
        """Sample in ``loop``'s ticks as its handler ``name`` (:meth:`sample`),
        switched on only while the scope acquires: a scope at rest costs the
        loop nothing."""
        loop.attach(self.sample, name=name, enabled=self._acquiring)
        sample = self.sample
        self._switch = lambda on: loop.enable(sample, on)

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
        if now_ns >= self._stream_next:
            self._offer(now_ns)
        self._staged += 1
        if self._staged >= _STAGE:
            self._flush()

    def _offer(self, now_ns: int) -> None:
        """Hand the sample just taken to each sink it is due at; each one's next
        is due a period on."""
        off = self._staged * self._row
        row = bytes(self._stage[off:off + self._row])
        soonest = _NEVER
        for slot in self._sinks:
            sink, due = slot
            if now_ns >= due:
                sink.offer(self._layout, row)
                nxt = (due or now_ns) + sink.period_ns  # 0: the first, just now
                slot[1] = due = nxt if nxt > now_ns else now_ns + sink.period_ns
            soonest = min(soonest, due)
        self._stream_next = soonest

    # -- the live sinks (application side) -------------------------------------------

    def _plug(self, attr: str, sink: Sink | None) -> Sink | None:
        old = getattr(self, attr)
        setattr(self, attr, sink)
        if sink is not None:
            sink.bind(self)
        self._sinks = [[s, 0] for s in (self.stream, self.foxglove) if s is not None]
        self._stream_next = 0 if self._sinks else _NEVER
        return old

    def start_stream(self, stream: UdpStream) -> UdpStream | None:
        """Stream the samples (from the next one on) to ``stream``; the stream it
        replaces, if any (the caller closes it, outside the loop)."""
        return self._plug("stream", stream)  # type: ignore[return-value]

    def stop_stream(self) -> UdpStream | None:
        """Stream no more; the stream that was on, if any (the caller closes it)."""
        return self._plug("stream", None)  # type: ignore[return-value]

    def start_foxglove(self, server: Sink) -> Sink | None:
        """Serve the samples (from the next one on) on a Foxglove server; the one
        it replaces, if any (the caller closes it, outside the loop)."""
        return self._plug("foxglove", server)

    def stop_foxglove(self) -> Sink | None:
        """Serve no more; the server that was on, if any (the caller closes it)."""
        return self._plug("foxglove", None)

    def close(self) -> None:
        """Close the live sinks the scope feeds: ``scope stream``'s socket and
        thread, ``scope foxglove``'s server and thread (what they held queued is
        sent first).  The station calls it on its way out, once the loop has
        stopped sampling.  Safe to call twice; it never raises, so that a sink
        that fails to close keeps neither the other one open nor the station
        from closing (the failure goes to the ``pyrt.scope`` log)."""
        for what, unplug in (("scope stream", self.stop_stream),
                             ("scope foxglove", self.stop_foxglove)):
            sink = unplug()
            if sink is None:
                continue
            try:
                sink.close()
            except Exception:  # a third-party SDK's error: logged, the rest still closes
                log.exception("%s: closing %r failed", what, sink)

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
        if n >= 2:
            self.sample_ns = int(tblock[-1] - tblock[0]) // (n - 1)
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
                hit = None
                if col is not None and trig is not None:
                    if start > max(j, 0):
                        self._note_missed(col, max(j, self._arm_g - g0, 0), min(start, n), g0,
                                          trig)
                    hit = self._find_edge(col, start, trig)
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
                trig_g = self._trig_g
                assert trig_g is not None, "a scope triggered without its trigger sample"
                end = trig_g + post
                if self._g < end:
                    break
                self._complete(trig_g - pre, pre)
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

    def _note_missed(self, col: np.ndarray, lo: int, hi: int, g0: int, trig: Trigger) -> None:
        """Count the trigger events in ``col[lo:hi]``, samples of the pre-trigger
        fill (not taken), and keep the time of the latest."""
        hits = self._edges(col, lo, hi, trig)
        if hits.size:
            self.missed += int(hits.size)
            self.missed_t_ns = int(self._ring_t[(g0 + lo + int(hits[-1])) % self._ring.shape[0]])

    def _edges(self, col: np.ndarray, start: int, end: int, trig: Trigger) -> np.ndarray:
        """Indices (from ``start``) of the crossings of ``trig`` in ``col[start:end]``."""
        start = max(start, 0)
        if start >= end:
            return np.empty(0, dtype=np.intp)
        prev = np.empty(end - start)
        prev[1:] = col[start : end - 1]
        if start > 0:
            prev[0] = col[start - 1]
        else:
            prev[0] = self._prev if self._prev is not None else np.nan
        cur = col[start:end]
        if trig.edge == "rising":
            return np.flatnonzero((prev < trig.level) & (cur >= trig.level))
        return np.flatnonzero((prev > trig.level) & (cur <= trig.level))

    def _find_edge(self, col: np.ndarray, start: int, trig: Trigger) -> int | None:
        hits = self._edges(col, start, col.shape[0], trig)
        return int(hits[0]) + max(start, 0) if hits.size else None

    def _span(self, first_g: int, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Copies of the times and values of samples ``first_g`` .. ``first_g + n - 1``
        (at most two contiguous slices of the ring)."""
        size = self._ring.shape[0]
        nch = len(self._names)
        start = first_g % size
        end = start + n
        if end <= size:
            return self._ring_t[start:end].copy(), self._ring[start:end, :nch].copy()
        wrap = end - size
        return (np.concatenate((self._ring_t[start:], self._ring_t[:wrap])),
                np.concatenate((self._ring[start:, :nch], self._ring[:wrap, :nch])))

    def _complete(self, first_g: int, trigger_index: int | None,
                  count: int | None = None) -> None:
        t_ns, data = self._span(first_g, self.capacity if count is None else count)
        self._frame = Frame(
            t_ns=t_ns,
            data=data,
            channels=tuple(self._names),
            trigger_index=trigger_index,
            mode=self.mode,
            units=tuple(src.units for src in self._sources),
            formats=tuple(src.fmt for src in self._sources),
        )
        self.frames += 1

    # -- read-out (application side) -----------------------------------------

    def read(self, last: int | None = None) -> Frame | None:
        """What the scope shows now, drawn as it comes (as halscope draws its
        trace), or None while there is nothing to show; only its ``last`` samples
        if given (the work is then bounded by ``last``, whatever the record length):

        * roll, and auto without a trigger while acquiring: the latest samples,
          up to a frame length (fewer while the first frame length fills);
        * the latest complete frame, if there is one;
        * else, while acquiring, the frame so far: after the trigger, the samples
          from the frame's start (its pre-trigger part) with the trigger point; in
          auto mode still waiting for its trigger, the samples since it was armed;
          normal and single modes show nothing before their trigger.
        """
        if last is not None and (isinstance(last, bool) or not isinstance(last, int)
                                 or last < 0):
            raise CommandError(f"a number of samples is a whole number >= 0, got {last!r}")
        self._flush()
        if self.mode == "roll" or (self.mode == "auto" and self.trigger is None
                                   and self._acquiring):
            return self._latest(max(0, self._g - self.capacity), None, last)
        if self._frame is not None or not self._acquiring:
            return _tail(self._frame, last)
        if self.state == "triggered" and self._trig_g is not None:
            first = max(self._trig_g - self.pre_samples, self._g - self.capacity, 0)
            return self._latest(first, self._trig_g - first, last)
        if self.mode == "auto":
            return self._latest(max(self._arm_g, self._g - self.capacity), None, last)
        return None

    def _latest(self, first_g: int, trigger_index: int | None,
                last: int | None = None) -> Frame | None:
        """The samples from ``first_g`` to the latest (only the ``last`` of them if
        given), as a frame (None if none)."""
        if last is not None and self._g - first_g > last:
            cut = self._g - last - first_g
            first_g += cut
            trigger_index = (None if trigger_index is None or trigger_index < cut
                             else trigger_index - cut)
        n = self._g - first_g
        if n <= 0:
            return None
        t_ns, data = self._span(first_g, n)
        return Frame(
            t_ns, data, tuple(self._names), trigger_index, self.mode,
            units=tuple(src.units for src in self._sources),
            formats=tuple(src.fmt for src in self._sources),
        )


def _tail(frame: Frame | None, last: int | None) -> Frame | None:
    """``frame``'s last ``last`` samples (the whole frame if ``last`` is None)."""
    if frame is None or last is None or frame.t_ns.size <= last:
        return frame
    cut = frame.t_ns.size - last
    index = frame.trigger_index
    return replace(frame, t_ns=frame.t_ns[cut:].copy(), data=frame.data[cut:].copy(),
                   trigger_index=None if index is None or index < cut else index - cut)
