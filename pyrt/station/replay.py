"""Replaying a journal: the station built again, fed the recorded inputs, checked tick by tick.

A :class:`Replay` reads a journal (:mod:`pyrt.journal`), and, given the
station the journal's header names built on the loop it provides (a
:class:`ReplayClock` gives each tick its recorded time) with boards from
the ``replay:`` back end (:func:`open_replay`: the process image fed from
the journal instead of a world; a world that the station builds for
``sim:`` boards stands still), runs it tick by tick:

* before the tick, the clock takes the next recorded tick: its time and its
  inputs (which the read phase brings in);
* in the mailbox's place, the requests recorded in that tick are applied
  (:func:`~pyrt.station.recording.decode_request`);
* after the write phase, the outputs the controller wrote are compared with
  the recorded ones, write by write (register, value), and so are the
  faults (the same tick, the same message).

The first difference ends the replay: :class:`Difference` names the tick,
the register, the recorded and the replayed value, and the task that wrote
each.  Otherwise it ends with "replayed N ticks, identical" (and says if the
journal ended early, or where a gap makes the rest unreplayable).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pyrt.boards.registers import BoardKind
from pyrt.boards.registry import (
    Boards,
    BoardURL,
    image_boards,
    register_backend,
    unregister_backend,
)
from pyrt.errors import ConfigError, Fault, PyrtError
from pyrt.journal import Gap, JournalError, JournalReader, Tick
from pyrt.scheduler.clock import Clock
from pyrt.station.recording import LOOP_FAULT, decode_request
from pyrt.station.snapshot import (
    Snapshot,
    SnapshotError,
    decompress_snapshot,
    restore_snapshot,
)

if TYPE_CHECKING:
    from pyrt.scheduler import Loop
    from pyrt.station.base import Station

__all__ = ["Difference", "Replay", "ReplayClock", "ReplayResult", "open_replay"]


class ReplayClock(Clock):
    """The clock of a replay: each tick at the time the journal recorded for
    it.  ``wait_until`` (the top of every tick) moves on to the next recorded
    tick (:attr:`advance`); nothing ever waits."""

    virtual = False

    def __init__(self, start_ns: int = 0):
        self._now = start_ns
        #: Called at the top of every tick; returns the tick's recorded time.
        self.advance: Callable[[], int] | None = None

    def now_ns(self) -> int:
        return self._now

    def wait_until(self, deadline_ns: int) -> None:
        if self.advance is not None:
            self._now = self.advance()


class _Feed:
    """The inputs of the tick being replayed (the image reads :attr:`current`)."""

    def __init__(self, inputs: list[int]):
        self.current = inputs


@dataclass(frozen=True)
class Difference:
    """Where the replay first did not do what the run did."""

    tick: int
    what: str
    register: str = ""
    recorded: str = ""
    replayed: str = ""
    recorded_by: str = ""
    replayed_by: str = ""

    def __str__(self) -> str:
        if not self.register:
            return f"tick {self.tick}: {self.what}"
        rec = self.recorded + (f" (written by {self.recorded_by})" if self.recorded_by else "")
        rep = self.replayed + (f" (written by {self.replayed_by})" if self.replayed_by else "")
        return f"tick {self.tick}: {self.what} {self.register}: recorded {rec}, replayed {rep}"


@dataclass(frozen=True)
class ReplayResult:
    """What a replay did: ticks replayed, and the first difference or None."""

    ticks: int
    first_tick: int | None
    last_tick: int | None
    difference: Difference | None
    notes: tuple[str, ...] = ()

    @property
    def identical(self) -> bool:
        return self.difference is None

    def line(self) -> str:
        """The one-line verdict."""
        if self.difference is not None:
            return f"replay differs at {self.difference} ({self.ticks} ticks replayed)"
        span = (f" (ticks {self.first_tick}..{self.last_tick})"
                if self.first_tick is not None else "")
        return f"replayed {self.ticks} ticks{span}, identical"


# -- the replay: back end ------------------------------------------------------------------------

_active: list[Replay] = []


def open_replay(url: BoardURL, station: str, kinds: dict[str, BoardKind],
                **options: Any) -> Boards:
    """The ``replay:`` back end: the boards of the journal being replayed (only
    while a :class:`Replay` builds its station)."""
    if not _active:
        raise url.error("replay: boards exist only while 'pyrt replay' builds a station")
    return _active[-1].open_boards(url, station, kinds, options)


class _Stop(Exception):
    pass


#: The header's metadata a replay reads, and what each must be (a recorder writes
#: them so; a journal from elsewhere may hold anything: refused, not obeyed).
_METADATA: dict[str, tuple[tuple[type, ...], str]] = {
    "factory": ((str,), "a station's name or MODULE:FACTORY"),
    "boards": ((str,), "a board URL"),
    "world": ((str,), "a world's name"),
    "fault": ((str,), "a fault's text"),
    "in_process": ((bool,), "true or false"),
    "tick_index": ((int,), "a tick number >= 0"),
    "inputs_before": ((list,), "a list of integers, one per input"),
    "args": ((dict,), "the run's options by name"),
}


def _check_metadata(path: str, meta: Mapping[str, Any]) -> None:
    """JournalError naming the first metadata field that is not as a recorder writes it."""
    for key, (types, what) in _METADATA.items():
        if key not in meta or meta[key] is None:
            continue
        v = meta[key]
        ok = isinstance(v, types) and not (bool not in types and isinstance(v, bool))
        if ok and key == "tick_index":
            ok = v >= 0
        elif ok and key == "inputs_before":
            ok = all(isinstance(x, int) and not isinstance(x, bool) for x in v)
        if not ok:
            raise JournalError(f"journal {path}: its header's {key} is {str(v)[:40]!r}, not "
                               f"{what} (not a journal pyrt wrote); not replayed")


class Replay:
    """Replays the journal at ``path`` (see the module text).

    Use: ``r = Replay(path)``; build the station with ``r.clock`` in its
    loop and ``r.url`` as its board URL inside ``with r.building():``;
    ``r.attach(station)``; then :meth:`run`.  JournalError for a damaged
    journal (with the offset), ConfigError for one this station cannot replay.
    """

    url = "replay:"

    def __init__(self, path: str | Path):
        self.path = str(path)
        self.reader = JournalReader(self.path)
        if self.reader.damage:  # never replayed silently: say where
            d = self.reader.damage[0]
            raise JournalError(f"journal {self.path}: damaged at offset {d.offset} (frame "
                               f"{d.frame}: {d.reason}); not replayed", d.offset, d.frame)
        self.header = self.reader.header
        meta = self.header.metadata
        self.meta: Mapping[str, Any] = meta if isinstance(meta, Mapping) else {}
        _check_metadata(self.path, self.meta)
        self.clock = ReplayClock()
        #: The controller's state the replay resumes from (a black box), or None.
        self.resume: Snapshot | None = None
        #: Why a black box cannot be resumed: its station could not save its state.
        self.refusal = ""
        self._resume_from_snapshot()
        before = list(self.meta.get("inputs_before") or [])
        if self.resume is not None:
            before = list(self.resume.inputs)
        if len(before) != len(self.header.inputs):
            before = [0] * len(self.header.inputs)
        self.feed = _Feed(before)
        self.station: Station | None = None
        self.boards: Boards | None = None
        self._records: Iterator[Tick | Gap] = iter(())
        self._expected: Tick | None = None
        self._gap: Gap | None = None
        self._writes: list[tuple[int, int, str]] = []
        self._faults: list[Fault] = []
        self.difference: Difference | None = None
        self.ticks = 0
        self.first_tick: int | None = None
        self.last_tick: int | None = None
        self._who: Callable[[], str] | None = None
        self._notes: list[str] = []
        self._pending: Tick | None = None

    def _resume_from_snapshot(self) -> None:
        """A journal that begins after its run began (a black box) resumes from the
        snapshot it carries; a damaged one is refused here, before anything is built."""
        if not self.reader.snapshots:
            return
        tick, data = self.reader.snapshots[0]
        try:
            snap = decompress_snapshot(data)
        except SnapshotError as exc:
            raise JournalError(f"journal {self.path}: its snapshot of tick {tick}: {exc}; "
                               "not replayed") from None
        if snap.refused:
            self.refusal = snap.refused
            return
        h = self.header
        if snap.tick != tick or len(snap.inputs) != len(h.inputs) \
                or len(snap.outputs) != len(h.outputs):
            raise JournalError(f"journal {self.path}: its snapshot of tick {tick} does not fit "
                               f"its journal (tick {snap.tick}, {len(snap.inputs)} inputs, "
                               f"{len(snap.outputs)} outputs); not replayed")
        self.resume = snap

    # -- building ------------------------------------------------------------------------------

    @property
    def factory(self) -> str:
        """The station factory the journal was recorded with (an installed
        station's name, or MODULE:FACTORY)."""
        return str(self.meta.get("factory") or self.header.station)

    @property
    def arguments(self) -> dict[str, Any]:
        """The station's options as the run had them."""
        args = self.meta.get("args")
        return dict(args) if isinstance(args, Mapping) else {}

    def write_databases(self, directory: Path) -> bool:
        """Write the databases the journal holds into ``directory``; whether there were any."""
        for name, data in self.header.databases.items():
            if Path(name).name != name or name in ("", ".", ".."):
                raise ConfigError(f"journal {self.path}: a database named {name!r} is not a "
                                  "file name")
            (directory / name).write_bytes(data)
        return bool(self.header.databases)

    def building(self) -> _Building:
        """The context in which the station is built (its ``replay:`` boards exist)."""
        return _Building(self)

    def open_boards(self, url: BoardURL, station: str, kinds: dict[str, BoardKind],
                    options: Mapping[str, Any]) -> Boards:
        """The station's boards: the image fed from the journal (see the module text)."""
        h = self.header
        layout = [(b, reg.name, reg.count) for b, kind in kinds.items() for reg in kind.inputs()]
        names = [f"{b}.{r}" if c == 1 else f"{b}.{r}[{i}]" for b, r, c in layout
                 for i in range(c)]
        if names != list(h.inputs):
            raise ConfigError(f"journal {self.path}: its inputs ({len(h.inputs)}: "
                              f"{', '.join(list(h.inputs)[:4])} ...) are not those of the "
                              f"{station} station's boards ({len(names)}: "
                              f"{', '.join(names[:4])} ...)")
        outs = [(b, reg.name, i) for b, kind in kinds.items() for reg in kind.outputs()
                for i in range(reg.count)]
        if len(outs) != len(h.outputs):
            raise ConfigError(f"journal {self.path}: {len(h.outputs)} outputs, the "
                              f"{station} station's boards have {len(outs)}")
        values = list(h.output_values) or [0] * len(outs)
        if self.resume is not None:
            values = list(self.resume.outputs)
        initial = dict(zip(outs, values, strict=True))
        simulated = None
        if self.meta.get("in_process", False):
            simulated = Boards(url.text, station, {n: k.sim() for n, k in kinds.items()}, kinds,
                               in_process=True, world="sim")
        world = str(self.meta.get("world") or "")
        info = None
        if simulated is None:  # the run's world was elsewhere: 'sim' says what a replay knows
            def info() -> dict[str, str]:
                return {"world": f"{world or 'elsewhere'} (not replayed: its inputs are)"}
        boards = image_boards(url.text, station, kinds, None, options, simulated=simulated,
                              feed=self.feed, outputs=initial, world=world, info=info)
        self.boards = boards
        return boards

    def attach(self, station: Station) -> None:
        """Hook the replay into the built ``station`` (before :meth:`run`)."""
        boards = station.boards
        if boards is None or boards is not self.boards:
            raise ConfigError("the station was not built on the replay's boards")
        runner = station.runner
        if runner is None:
            raise ConfigError("the station has no runner (adopt() it first)")
        self.station = station
        loop = station.loop
        if loop.period_ns != self.header.period_ns:
            raise ConfigError(f"journal {self.path}: ticks of {self.header.period_ns} ns, the "
                              f"loop's are {loop.period_ns} ns")
        self._who = loop.writer
        image = boards.image
        image.tap = self
        runner.replayed = self._requests
        loop.fault_listeners.append(self._faults.append)
        loop.attach(self._check, name="replay:check")
        self.clock.advance = self._advance
        if self.resume is not None:
            self._resume(station)
            boards.resync()
            return
        self._records = iter(self.reader)
        first = self._peek_first()
        start = int(self.meta.get("tick_index", 0) or 0)
        if first is not None and first.tick != loop.tick_index:
            if self.refusal:
                why = (f" (a black box whose station could not save its state there: "
                       f"{self.refusal})")
            elif first.tick != start:
                why = (" (a black box without a snapshot: it holds the last seconds of a "
                       "run, which cannot be replayed without the ticks before them)")
            else:
                why = ""
            raise ConfigError(f"journal {self.path} begins at tick {first.tick}; a replay "
                              f"starts where the run started, at tick {loop.tick_index}{why}")
        boards.resync()

    def _resume(self, station: Station) -> None:
        """Start at the snapshot's tick, the controller as the snapshot has it."""
        snap = self.resume
        assert snap is not None
        self._records = self.reader.seek(snap.tick)
        first = self._peek_first()
        if first is None or first.tick != snap.tick:
            raise ConfigError(f"journal {self.path}: its snapshot is of tick {snap.tick}, "
                              "which the journal does not hold; not replayed")
        try:
            restore_snapshot(station, snap)
        except SnapshotError as exc:
            raise SnapshotError(f"journal {self.path}: its snapshot of tick {snap.tick}: "
                                f"{exc}; not replayed") from None
        image = self.boards.image if self.boards is not None else None
        if image is not None:  # what building the station wrote is not what the run had
            image.forget_outputs(dict(zip(image.output_layout, snap.outputs, strict=True)))
        # the loop's time as the snapshot has it, and the deadline of the first tick
        # replayed as the run had it
        station.loop.resume_at(snap.time_ns, first.time_ns - first.lateness_ns)
        self.clock._now = snap.time_ns

    def _peek_first(self) -> Tick | None:
        for rec in self._records:
            if isinstance(rec, Gap):
                self._gap = rec
                return None
            self._pending = rec
            return rec
        return None

    # -- the taps ------------------------------------------------------------------------------

    def wrote(self, slot: int, value: int) -> None:
        """The controller changed output ``slot`` to ``value``."""
        assert self._who is not None
        self._writes.append((slot, value, self._who()))

    def _requests(self) -> list[Callable[[], Any]]:
        t = self._expected
        if t is None or not t.commands:
            return []
        assert self.station is not None
        calls = []
        for c in t.commands:
            try:
                calls.append(decode_request(self.station, c.text))
            except PyrtError as exc:
                self._differ(Difference(t.tick, f"the recorded request {c.text[:80]!r} "
                                                f"(from {c.source}) cannot be applied: {exc}"))
        return calls

    # -- the run -------------------------------------------------------------------------------

    def _advance(self) -> int:
        rec: Tick | Gap | None = self._pending
        self._pending = None
        if rec is None:
            rec = next(self._records, None)
        if isinstance(rec, Gap):
            self._gap = rec
            rec = None
        if rec is None:  # run() counts the ticks: this is not reached while ticks remain
            raise _Stop
        self._expected = rec
        self.feed.current = list(rec.inputs)
        for e in rec.events:  # the clock's decision after the previous tick, taken again
            if e.name == LOOP_FAULT and self.station is not None:
                self.station.loop.fault_all(e.message, source="loop")
        return rec.time_ns

    def _differ(self, d: Difference) -> None:
        if self.difference is None:
            self.difference = d
        assert self.station is not None
        self.station.loop.stop()

    def _name(self, slot: int) -> str:
        return self.header.outputs[slot]

    def _writer(self, index: int) -> str:
        writers = self.reader.writers
        return writers[index] if 0 <= index < len(writers) else f"writer {index}"

    def _check(self, now_ns: int) -> None:
        t = self._expected
        if t is None:
            return
        writes, self._writes = self._writes, []
        faults = self._faults[:]
        self._faults.clear()
        rec = t.outputs
        for k in range(max(len(rec), len(writes))):
            r = rec[k] if k < len(rec) else None
            w = writes[k] if k < len(writes) else None
            if r is not None and w is not None and r[0] == w[0] and r[1] == w[1]:
                continue
            if r is None:
                assert w is not None
                self._differ(Difference(t.tick, "output", self._name(w[0]), "not written",
                                        f"{w[1]}", "", w[2]))
            elif w is None:
                self._differ(Difference(t.tick, "output", self._name(r[0]), f"{r[1]}",
                                        "not written", self._writer(r[2]), ""))
            elif r[0] != w[0]:
                self._differ(Difference(t.tick, "output", self._name(r[0]), f"{r[1]}",
                                        f"{self._name(w[0])} written instead ({w[1]})",
                                        self._writer(r[2]), w[2]))
            else:
                self._differ(Difference(t.tick, "output", self._name(r[0]), f"{r[1]}",
                                        f"{w[1]}", self._writer(r[2]), w[2]))
            return
        recorded = [(e.name, e.message) for e in t.events if e.name != LOOP_FAULT]
        replayed = [("fault", str(f)) for f in faults]
        if recorded != replayed:
            self._differ(Difference(
                t.tick, "events: recorded "
                + ("; ".join(f"{n} {m!r}" for n, m in recorded) or "none")
                + ", replayed " + ("; ".join(f"{n} {m!r}" for n, m in replayed) or "none")))
            return
        self.ticks += 1
        if self.first_tick is None:
            self.first_tick = t.tick
        self.last_tick = t.tick

    def run(self, until: int | None = None) -> ReplayResult:
        """Replay every recorded tick (up to and including tick ``until``), or
        until the first difference."""
        station = self.station
        if station is None:
            raise ConfigError("attach() the station first")
        summary = self.reader.summary()
        last = summary.last_tick
        if self._gap is not None:
            last = None
        elif self.reader.gaps:
            g = self.reader.gaps[0]
            last = (g.first - 1) if g.first is not None else last
        if until is not None:
            if last is not None and until > last:
                self._notes.append(f"the journal ends at tick {last}, before tick {until}")
            else:
                last = until
        loop: Loop = station.loop
        n = 0 if last is None else max(0, last - loop.tick_index + 1)
        with contextlib.suppress(_Stop):  # the journal ran out of ticks
            loop.run(n)
        notes = list(self._notes)
        if self.resume is not None:
            first = self.reader.summary().first_tick
            skipped = self.resume.tick - (first if first is not None else self.resume.tick)
            notes.insert(0, f"a black box: resumed from its snapshot of the controller at tick "
                            f"{self.resume.tick}" + (f" (the {skipped} ticks before it are "
                                                    "in the file, not replayed)"
                                                    if skipped else ""))
        if self.difference is None:
            gap = self._gap or (self.reader.gaps[0] if self.reader.gaps else None)
            if gap is not None and (until is None or (gap.first or 0) <= until):
                notes.append(f"not replayable past tick {gap.first}: {gap.cause}")
            if until is None and not self.reader.complete:
                why = self.reader.ended_early or "the journal has no end record"
                notes.append(f"{why}: the run was cut off; replayed up to its last "
                             "complete tick")
        return ReplayResult(self.ticks, self.first_tick, self.last_tick, self.difference,
                            tuple(notes))

    def close(self) -> None:
        """Detach from the station (its boards are closed with it)."""
        if self.boards is not None and self.boards.image is not None \
                and self.boards.image.tap is self:
            self.boards.image.tap = None


class _Building:
    def __init__(self, replay: Replay):
        self.replay = replay

    def __enter__(self) -> Replay:
        if not _active:
            register_backend("replay", open_replay)
        _active.append(self.replay)
        return self.replay

    def __exit__(self, *exc: object) -> None:
        _active.remove(self.replay)
        if not _active:
            unregister_backend("replay")

