"""A station's flight recorder: its journal (``--journal FILE``) and its black box.

A :class:`Recorder` taps the three doors through which anything enters a
running station (:mod:`pyrt.journal` has the file format):

* the **process image** (:class:`~pyrt.boards.image.ImageBackend`): every
  input of every tick, as the read phase brought it in, and every output
  the tick changed, with the task that wrote it (as the loop names it,
  :meth:`~pyrt.scheduler.loop.Loop.writer`: the routine a ready queue is
  dispatching, else the handler or foreground job running);
* the **mailbox** (:class:`~pyrt.scheduler.runner.Runner`): every request
  applied, in the tick it was applied in, as a replayable text
  (:func:`encode_request`);
* the **clock**: the tick's index, time, lateness and the deadlines missed
  before it; and the faults, as events.

It hands each tick to a :class:`~pyrt.journal.Journal` (whose thread
encodes and writes: the loop never waits for the disk) at the end of the
tick, after the write phase: at the end of the image's write phase when
that is the tick's last work (boards in this process: no handler of its
own), else as the loop's last handler, ``journal``.  A plain tick (nothing
written, asked, faulted or missed, the journal open and its ring not full,
no tick listener due) is one C call when the image keeps its inputs in
64-bit integers (its boards' register files are so): the clock and a copy
of the inputs into the journal's ring, made by the image's write phase
itself, no Python frame (:class:`~pyrt.native.TickHandOver`).  The
recorder's taps, the journal's writer (a write error) and
:meth:`Recorder.listen_at` mark that hand-over slow or due, and the tick
then takes the recorder's own path.  The C side knows the tick it expects
(index and deadline, set again by every tick that takes that path), and a
tick whose lateness against it is out of bounds is not plain: on virtual
time any lateness (a deadline moved between runs), at real time half a
period or more (a deadline skipped: the ticks missed are counted there).
A real-time loop restarted less than half a period after the deadline it
stopped before starts at once (``Loop.run``): its first tick's lateness is
then taken from the deadline it stopped before.  A statistics reset
(``Loop.reset_statistics``) is seen at the next tick that takes the
recorder's path (the next deadline skipped at the latest): a count of
missed deadlines that went down, moved further than the deadline, or stood
still though the last tick overran was reset, and the tick records those
counted since.  Every back end
reaches its boards through a process image (``sim:`` included: one tick
shape, recorded or not).

Requests are recorded when they are calls of the station's or a
component's methods with arguments of plain types (numbers, text, lists,
components, commands, parameters, dataclass records of pyrt or of the
station's package): every command typed, every motion queued, ``stop``,
``ack``, ``set``.  Other requests (a console's lambdas that read signals)
are not: a request that changed the controller without being recorded
shows as a difference when the journal is replayed.
"""

from __future__ import annotations

import dataclasses
import importlib
import json
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pyrt._version import __version__
from pyrt.component import Component
from pyrt.errors import ConfigError, Fault
from pyrt.journal import DEFAULT_QUEUE_TICKS, BlackBox, Header, Journal
from pyrt.native import HAND_OVER_DUE, IMAGE_TMAX

if TYPE_CHECKING:
    from pyrt.station.base import Station

__all__ = ["LOOP_FAULT", "REPLAYED", "Recorder", "decode_request", "encode_request"]

#: The requests a journal records and a replay applies: what the consoles, the DAQ
#: server and EPICS ask of a station (its command records run through ``execute``)
#: and of a level (``enter_level``).  Nothing else is called from a journal: a
#: journal from elsewhere names no method of one's choosing.
REPLAYED = frozenset({
    "execute", "submit_motion", "acknowledge", "stop", "stop_all",
    "set_param", "watch_move", "enter_level", "reflex", "trip",
    # reads, replayed as they were made (they change nothing; a read that did would show)
    "status", "status_fields", "busy", "param", "params_of", "where", "last_stop",
})

#: How often the journal's writer looks for ticks at real time, seconds (a block
#: being filled is cut 0.5 s after its first tick whatever the poll: the writer wakes
#: for it).  A wake-up costs the writer ~0.16 ms of CPU on the gripper whatever it
#: takes: 4 a second cost half of 10.
REALTIME_POLL_S = 0.25

#: The event of a fault the loop itself declared (consecutive overruns): the
#: clock's decision, which a replay applies rather than checks.
LOOP_FAULT = "loop-fault"


class _Listeners(list):  # type: ignore[type-arg]
    """The recorder's tick listeners: one added is called at the next tick."""

    def __init__(self, added: Callable[[], None]):
        super().__init__()
        self._added = added

    def append(self, listener: Any) -> None:
        super().append(listener)
        self._added()

    def extend(self, listeners: Any) -> None:
        super().extend(listeners)
        self._added()

    def insert(self, index: Any, listener: Any) -> None:
        super().insert(index, listener)
        self._added()


# -- requests as text ----------------------------------------------------------------------


class _Unrecordable(Exception):
    pass


def _allowed_roots(station: Station) -> set[str]:
    return {"pyrt", type(station).__module__.split(".")[0]}


def _enc(station: Station, v: Any) -> Any:
    if v is None or isinstance(v, bool | int | str):
        return v
    if isinstance(v, float):
        return v
    if isinstance(v, Component):
        return {"$c": v.name}
    if isinstance(v, tuple) and not hasattr(v, "_fields"):
        return {"$t": [_enc(station, x) for x in v]}
    if isinstance(v, list):
        return [_enc(station, x) for x in v]
    if isinstance(v, dict) and all(isinstance(k, str) for k in v):
        return {"$d": {k: _enc(station, x) for k, x in v.items()}}
    kind = type(v).__name__
    if kind == "Command" and hasattr(v, "handler") and hasattr(v, "parse"):
        return {"$r": v.name}
    if kind == "Param" and hasattr(v, "describe"):
        return {"$p": v.name}
    if dataclasses.is_dataclass(v) and not isinstance(v, type):
        cls = type(v)
        if cls.__module__.split(".")[0] not in _allowed_roots(station):
            raise _Unrecordable(cls.__qualname__)
        return {"$dc": f"{cls.__module__}:{cls.__qualname__}",
                "f": {f.name: _enc(station, getattr(v, f.name))
                      for f in dataclasses.fields(v) if f.init}}
    raise _Unrecordable(kind)


def encode_request(station: Station, name: str, fn: Callable[..., Any] | None, args: tuple,
                   motion: Any = None) -> str | None:
    """The replayable text of one mailbox request, or None if it cannot be
    recorded (not a method of the station or of one of its components, or an
    argument of a type that has no text)."""
    try:
        if motion is not None:
            return json.dumps({"motion": _enc(station, motion)}, separators=(",", ":"))
        owner = getattr(fn, "__self__", None)
        method = getattr(fn, "__name__", "")
        if owner is None or method not in REPLAYED:
            return None
        if owner is station:
            who = ""
        elif isinstance(owner, Component) and station.find(owner.name) is owner:
            who = owner.name
        else:
            return None
        return json.dumps({"o": who, "m": method, "a": [_enc(station, a) for a in args]},
                          separators=(",", ":"))
    except (_Unrecordable, ValueError, TypeError):
        return None


def _dec(station: Station, v: Any, comp: list[Component | None]) -> Any:
    if isinstance(v, list):
        return [_dec(station, x, comp) for x in v]
    if not isinstance(v, dict):
        return v
    if "$c" in v:
        c = station.component(v["$c"])
        comp[0] = c
        return c
    if "$t" in v:
        return tuple(_dec(station, x, comp) for x in v["$t"])
    if "$d" in v:
        return {k: _dec(station, x, comp) for k, x in v["$d"].items()}
    if "$r" in v:
        for c, rec in station.all_commands():
            if rec.name == v["$r"] and (comp[0] is None or c is comp[0]):
                return rec
        raise ConfigError(f"no command {v['$r']!r}")
    if "$p" in v:
        if comp[0] is None:
            raise ConfigError(f"parameter {v['$p']!r} without its object")
        for p in station.params_of(comp[0]):
            if p.name == v["$p"]:
                return p
        raise ConfigError(f"no parameter {comp[0].name}.{v['$p']}")
    if "$dc" in v:
        module, _, qual = str(v["$dc"]).partition(":")
        if module.split(".")[0] not in _allowed_roots(station):
            raise ConfigError(f"a record of {module!r} is not replayed")
        obj: Any = importlib.import_module(module)
        for part in qual.split("."):
            obj = getattr(obj, part)
        return obj(**{k: _dec(station, x, comp) for k, x in v["f"].items()})
    raise ConfigError(f"unknown value {v!r}")


def decode_request(station: Station, text: str) -> Callable[[], Any]:
    """The call that applies a recorded request (:func:`encode_request`) to
    ``station``; ConfigError if the station has no such method or object."""
    try:
        data = json.loads(text)
    except ValueError:
        raise ConfigError(f"recorded request {text[:60]!r} is not JSON") from None
    comp: list[Component | None] = [None]
    if "motion" in data:
        record = _dec(station, data["motion"], comp)
        runner = station.runner
        assert runner is not None
        return lambda: runner.motion.put(record)
    who, method = data.get("o", ""), data.get("m", "")
    owner: Any = station if not who else station.component(who)
    if not isinstance(method, str) or method not in REPLAYED:
        raise ConfigError(f"recorded request names no method a journal replays: "
                          f"{text[:60]!r}")
    fn = getattr(owner, method, None)
    if not callable(fn):
        raise ConfigError(f"{type(owner).__name__} has no method {method!r}")
    args = [_dec(station, a, comp) for a in data.get("a", [])]
    return lambda: fn(*args)


# -- the recorder ----------------------------------------------------------------------------


class Recorder:
    """Records ``station`` into a journal at ``path`` and/or a black box (see
    the module text).  Build it after the station (its handlers attached),
    before the loop starts; :meth:`close` ends the journal.

    ``metadata``: what a replay needs to build the station again (the
    factory, the command line), kept in the header.  ``lossless``: the loop
    waits for the journal's writer rather than leave a gap (a run on
    virtual time, where waiting costs nothing).
    """

    def __init__(self, station: Station, path: str | Path | None, *,
                 black_box: BlackBox | None = None, metadata: Mapping[str, Any] | None = None,
                 lossless: bool | None = None, warn: Callable[[str], None] | None = None):
        boards = station.boards
        image = getattr(boards, "image", None)
        if image is None:
            raise ConfigError("a journal records the process image: these boards have none")
        runner = station.runner
        if runner is None:
            raise ConfigError("a journal records a built station: adopt() it first")
        self.station = station
        self.image = image
        loop = station.loop
        self.loop = loop
        #: Who is writing now (the running routine or handler): the loop says.
        self._writer = loop.writer
        meta = dict(metadata or {})
        meta.setdefault("boards", boards.url if boards is not None else "")
        meta.setdefault("in_process", bool(boards is not None and boards.in_process))
        meta.setdefault("world", boards.world if boards is not None else "")
        meta["inputs_before"] = [image.read(b, r, i) for b, r, c in image.layout
                                 for i in range(c)]
        meta["fault"] = str(station.fault) if station.fault is not None else ""
        meta["tick_index"] = loop.tick_index
        header = Header(
            station=station.name, period_ns=loop.period_ns,
            inputs=[f"{b}.{r}" if c == 1 else f"{b}.{r}[{i}]"
                    for b, r, c in image.layout for i in range(c)],
            outputs=[f"{b}.{r}" if self._count(b, r) == 1 else f"{b}.{r}[{i}]"
                     for b, r, i in image.output_layout],
            output_values=image.output_values(), version=__version__,
            databases=station.journal_databases(), seeds=station.seeds(),
            writers=loop.writer_names(),
            metadata=meta)
        self.header = header
        lossless = loop.clock.virtual if lossless is None else lossless
        # at real time the writer wakes a few times a second (and when a block is due
        # to be cut, 0.5 s after its first tick): each wake-up takes the interpreter
        # from a loop that may be about to tick; but at least eight times per
        # queue's worth of ticks, so
        # that a fast tick (50 µs: 4096 ticks are 0.2 s) keeps room for a writer
        # that the machine's load delays
        poll = min(REALTIME_POLL_S, DEFAULT_QUEUE_TICKS * loop.period_ns / 8e9)
        self.journal = Journal(header, path, black_box=black_box, lossless=lossless,
                               poll_s=0.02 if lossless else poll, warn=warn)
        self._inputs: list[int] = list(meta["inputs_before"])
        #: The journal's index of each writer's name (its table only grows).
        self._writer_index: dict[str, int] = {}
        self._outputs: list[tuple[int, int, int]] = []
        self._commands: list[tuple[str, str]] = []
        self._events: list[tuple[str, int, str]] = []
        self._missed = loop.missed
        #: Whether the hand-over's expected deadline is set (by a tick of ours).
        self._expecting = False
        self._unrecorded = 0
        #: Files of the recorder's that could not be written (the journal, a
        #: black box), any thread: each is a fault of the station, tripped by
        #: the loop at the top of its next record (:meth:`disk_fault`).
        self._disk_faults: list[tuple[str, str]] = []
        self._journal_said = False
        #: Whether a tap brought something since the last record (outputs, requests,
        #: faults, a disk fault): the record takes the slow path.
        self._pending = False
        #: The journal's hand-over of a tick (bound once: called every tick).
        self._record = self.journal.record_owned
        #: Called at the end of a tick, after it was handed to the journal:
        #: ``listener(tick_index, now_ns)``, which returns the next tick it wants to
        #: be called at (None: every tick); the black box samples and dumps from here.
        #: One added is first called at the next tick.
        self.tick_listeners: list[Callable[[int, int], int | None]] = _Listeners(
            lambda: self.listen_at(0))
        #: The next tick at which the listeners are called.
        self._listen_at = IMAGE_TMAX
        #: A plain tick's hand-over in one C call, when the image's inputs are native
        #: 64-bit integers (None: the journal packs the image's list of inputs); its
        #: state (``slow``, the expected tick ...) is set by every tick that takes the
        #: recorder's own path, the first included.
        hand = self.journal.hand_over(image.native) \
            if getattr(image, "native", None) is not None else None
        self._hand = hand.state if hand is not None else None
        self._hand_call = hand.call if hand is not None else None
        if hand is not None:
            # on virtual time a tick starts on its deadline; at real time a skipped
            # deadline puts the next tick's start a period past the one expected
            late_hi = 0 if loop.clock.virtual else loop.period_ns // 2
            hand.state.late_lo, hand.state.late_hi = 0, late_hi
        image.tap = self
        runner.request_tap = self._request
        loop.fault_listeners.append(self._fault)
        #: Whether the tick is handed over at the end of the image's write phase (an
        #: image in this process whose write phase is the tick's last work: no
        #: handler of its own), else by the loop's last handler, ``journal``.
        self.in_write_phase = bool(
            hasattr(image, "after_write") and not image.has_link
            and loop.handler_names and loop.handler_names[-1] == "io:write"
            and station.board_sets and station.board_sets[-1].image is image)
        if self.in_write_phase:
            image.after_write = self._tick
            image.hand_over = self._hand_call
        else:
            loop.attach(self._tick_handler, name="journal")

    def _count(self, board: str, reg: str) -> int:
        return self.image.kinds[board].register(reg).count

    # -- taps (loop thread) --------------------------------------------------------------

    def wrote(self, slot: int, value: int) -> None:
        """Output ``slot`` was changed to ``value`` (by the task running now)."""
        name = self._writer()
        index = self._writer_index.get(name)
        if index is None:
            index = self._writer_index[name] = self.journal.writer_index(name)
        self._outputs.append((slot, value, index))
        self._pending = True
        if self._hand is not None:
            self._hand.slow = 1

    def _request(self, name: str, fn: Callable[..., Any] | None, args: tuple,
                 motion: Any) -> None:
        text = encode_request(self.station, name, fn, args, motion)
        if text is None:
            self._unrecorded += 1
            return
        self._commands.append((text, name))
        self._pending = True
        if self._hand is not None:
            self._hand.slow = 1

    def _fault(self, fault: Fault) -> None:
        if fault.source == "loop" and not any(
                n == LOOP_FAULT and m == fault.cause for n, _i, m in self._events):
            # a clock decision (consecutive overruns), taken after a tick: an input of
            # the replay, which trips the station at the same place
            self._events.append((LOOP_FAULT, fault.id, fault.cause))
        self._events.append(("fault", fault.id, str(fault)))
        self._pending = True
        if self._hand is not None:
            self._hand.slow = 1

    def disk_fault(self, cause: str, source: str) -> None:
        """A file of the recorder's could not be written (any thread): the station
        trips at the top of the loop's next record, with every motor stopped."""
        self._disk_faults.append((cause, source))
        self._pending = True
        if self._hand is not None:
            self._hand.slow = 1

    def _trip_disk_faults(self) -> None:
        journal = self.journal
        if journal.error is not None and not self._journal_said:
            self._journal_said = True
            self._disk_faults.append((f"journal {journal.path}: {journal.error}; "
                                      "the journal ends there", "JOURNAL"))
        while self._disk_faults:
            cause, source = self._disk_faults.pop(0)
            self.station.trip(cause, source=source)

    def _tick_handler(self, now_ns: int) -> None:
        """The loop's last handler, ``journal`` (when the image's write phase is not
        the tick's last work): the one C call, else :meth:`_tick`."""
        status = self._hand_call(now_ns) if self._hand_call is not None else -1
        if status:
            self._tick(now_ns, status)

    def _tick(self, now_ns: int, status: int = -1) -> None:
        # the tick the one C call did not take (``status``: its answer, -1 without
        # one): the image's write phase calls it so; or, answered HAND_OVER_DUE, a
        # tick it took whose listeners are due
        loop = self.loop
        if status == HAND_OVER_DUE:
            self._listen(loop.tick_index, now_ns)
            return
        hand = self._hand
        skipped = None
        if hand is not None:
            hand.slow = 0  # before anything reads what marks it (a tap, a write error)
            if self._expecting:
                # the deadlines skipped since the last record: the C side's expected
                # deadline is this tick's unless some were
                skipped = (loop.deadline_ns - hand.deadline_ns) // loop.period_ns
        if self._pending or loop.missed != self._missed or skipped \
                or self.journal.error is not None:
            self._pending = False
            self._tick_slowly(now_ns, skipped)
        else:
            # a tick with nothing to add: the ring full, the journal in a gap or
            # closed, a deadline skipped without a miss counted (start-up), the C
            # side's expected tick not set yet (the first), or a list of inputs
            self._record(loop.tick_index, now_ns, now_ns - loop.deadline_ns, 0,
                         self.image.last_inputs or self._inputs)
        if self.tick_listeners and loop.tick_index >= self._listen_at:
            self._listen(loop.tick_index, now_ns)
        if hand is not None:
            # the next tick as the loop will run it unless a deadline is skipped
            hand.tick = loop.tick_index + 1
            hand.deadline_ns = loop.deadline_ns + loop.period_ns
            self._expecting = True
            if self._pending or self.journal.error is not None:
                hand.slow = 1

    def listen_at(self, tick: int) -> None:
        """Call the tick listeners at tick ``tick`` at the latest (loop thread)."""
        if tick < self._listen_at:
            self._listen_at = tick
            if self._hand is not None:
                self._hand.listen_at = tick

    def _listen(self, tick: int, now_ns: int) -> None:
        """Call the tick listeners; the next call is at the earliest tick one asks for
        (none while there are none)."""
        due = IMAGE_TMAX
        for listener in list(self.tick_listeners):
            at = listener(tick, now_ns)
            if at is None or at <= tick:
                at = tick + 1
            due = min(due, at)
        self._listen_at = due
        if self._hand is not None:
            self._hand.listen_at = self._listen_at

    def _tick_slowly(self, now_ns: int, skipped: int | None = None) -> None:
        journal = self.journal
        loop = self.loop
        if self._disk_faults or (journal.error is not None and not self._journal_said):
            # before the record: the reflex's outputs are in it, written by the
            # recorder (not by the write phase whose end may be running now)
            running, loop.current = loop.current, "journal"
            try:
                self._trip_disk_faults()
            finally:
                loop.current = running
        missed = loop.missed
        # the deadlines missed since the last record: the count moved by them, and the
        # deadline by them at least (``skipped``, when known; a real-time run restarted
        # late moves it further, a start-up overrun counts none).  A count that went
        # down, moved further than the deadline, or stood still though the last tick
        # overran was reset since: those since then.
        delta = missed - self._missed
        if delta < 0 or (skipped is not None and delta > skipped) \
                or (skipped and not delta and loop.consecutive_overruns > 0):
            delta = missed
        missed, self._missed = delta, missed
        # the journal keeps the sequences it is given: an empty one is never handed
        # over (a later append would land in every tick still waiting to be written)
        outputs: Sequence[tuple[int, int, int]] = self._outputs
        if outputs:
            self._outputs = []
        else:
            outputs = ()
        commands: Sequence[tuple[str, str]]
        events: Sequence[tuple[str, int, str]]
        if self._commands or self._events:
            commands, events = self._commands or (), self._events or ()
            self._commands, self._events = [], []
        else:
            commands = events = ()
        self._record(loop.tick_index, now_ns, now_ns - loop.deadline_ns, missed,
                     self.image.last_inputs or self._inputs, outputs, commands, events)

    # -- any thread ---------------------------------------------------------------------------

    @property
    def unrecorded(self) -> int:
        """Requests applied that have no replayable text (reads, mostly)."""
        return self._unrecorded

    def close(self) -> None:
        """End the journal (flushed, synced, its end frame written); idempotent."""
        if self.image.tap is self:
            self.image.tap = None
        if self.in_write_phase and self.image.after_write == self._tick:
            self.image.after_write = None
            self.image.hand_over = None
        self.journal.close()
