"""A controller's state between two ticks, written into a black box so that it replays.

A black box (:mod:`pyrt.station.blackbox`) holds the last seconds of a run;
a replay of them must start from the controller as it stood at their first
tick.  A :class:`Snapshot` is that state, taken in the loop thread at the end
of a tick (after the write phase), as the state *before* the next one:

* the loop's own: the next tick's index, the fault ids given so far, each
  rate group's ticks to its next release, each ready queue's memory (its
  table and counters), whether its interrupts are on and whether it is halted;
* the station's: each robot's fault (and whether it was moving), the move
  watch's counters, the motion records queued;
* the controller's, as the station's hook gives it
  (:meth:`~pyrt.station.base.Station.snapshot_state` /
  :meth:`~pyrt.station.base.Station.restore_state`); the built-in stations
  give their component trees through :func:`state_of` / :func:`restore_into`;
* the process image's inputs as the last tick read them and its outputs as
  it left them.

The loop thread only copies what can change, and as few Python operations a
value as it can: each class's objects are read by a layout found once (the
names of their attributes, read by one ``attrgetter`` call and checked against
the object's own values by one comparison, without asking for ``__dict__``),
what each attribute needs is decided once per classes of the values (plain
values are kept as they are, in one list copy), lists of numbers are copied by
one C call, C memory by one ``memmove``, and a value that cannot change (a
tuple or a frozen record of such values) is encoded once while it is held; the
dicts of objects' attributes and the numbers of C memory are made only when the
snapshot is written (:meth:`Snapshot.encode`), in the thread that writes the
black box.

A station that cannot give some state raises :class:`SnapshotError` saying
which ("cannot snapshot: tiny has no snapshot", "cannot snapshot: the
foreground job init is running"); the black box then carries that reason and
``pyrt replay`` refuses it with it.

The format (``pyrt-snapshot/1``) is JSON, written zlib-compressed in the
journal's ``S`` frame (:mod:`pyrt.journal.format`)::

    {"format": "pyrt-snapshot/1", "station": NAME, "tick": T, "time_ns": NS,
     "inputs": [...], "outputs": [...], "loop": {...}, "station_state": {...},
     "state": {...}}            or  {"format": ..., "station": NAME, "refused": WHY}

Values are JSON numbers, strings, ``null``, ``true``/``false`` and lists, or
one-key objects naming their kind: ``{"$t": [...]}`` a tuple, ``{"$d": [[k,
v], ...]}`` a dict, ``{"$b": HEX}`` bytes, ``{"$ba": HEX}`` a bytearray,
``{"$a": [DTYPE, SHAPE, HEX]}`` a numpy array (``"ro": true`` beside it: a
read-only one, which is restored by a new read-only array; ``"is": PATH``: the
array given first at PATH, held here too), ``{"$n": [DTYPE, HEX]}`` a
numpy scalar, ``{"$q": [...]}`` a deque, ``{"$s": [...]}`` a set,
``{"$ev": BOOL}`` a threading event (set or not), ``{"$lk": 0}`` a lock (a
restored object that has none gets a new one, free),
``{"$cd": ...}`` the numbers in C memory a kernel owns (a list for an array,
an object of its fields for a struct; its pointers are left out),
``{"$e": "MODULE:CLASS", "v": NAME}`` an enum's member, ``{"$dc":
"MODULE:CLASS", "f": {...}}`` a dataclass record, ``{"$o": {...}, "$c":
"MODULE:CLASS"}`` an object's attributes, ``{"$r": PATH}`` an object given
earlier at PATH.  Floats keep every bit (JSON's shortest repr round-trips;
NaN and the infinities are JSON's ``NaN`` and ``Infinity``, as Python's
``json`` writes and reads them).  A record or an object is only
ever of a class of pyrt (or of the station's own package): a snapshot never
chooses code to run, it only sets attributes of the station the replay built.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import gc
import importlib
import json
import operator
import sys
import threading
import zlib
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from types import BuiltinFunctionType, CodeType, FunctionType, MethodType, ModuleType
from typing import TYPE_CHECKING, Any

import _cffi_backend  # type: ignore[import-untyped]  # C memory a kernel owns
import numpy as np

from pyrt.errors import ConfigError

if TYPE_CHECKING:
    from pyrt.station.base import Station

__all__ = ["SNAPSHOT_FORMAT", "Snapshot", "SnapshotError", "compress_snapshot",
           "decompress_snapshot", "plain_state", "restore_into", "restore_snapshot",
           "state_of", "take_snapshot"]

#: The snapshot format this pyrt writes and reads.
SNAPSHOT_FORMAT = "pyrt-snapshot/1"

#: Objects of these packages are structure, not state: the boards (the image
#: carries their registers), the simulated world (a replay's stands still), the
#: loop, queues and runner (their state is taken apart, :func:`_loop_state`),
#: the scope, the station and the databases; an arm's kinematic chains (a
#: constant description, its closed form and their kernels' scratch workspaces).
_STRUCTURE = ("pyrt.kinematics", "pyrt.native._kinematics", "pyrt.native._puma",
              "pyrt.boards", "pyrt.sim", "pyrt.scope", "pyrt.db", "pyrt.station.base",
              "pyrt.station.robots", "pyrt.station.events", "pyrt.station.requests",
              "pyrt.station.domain", "pyrt.station.moves", "pyrt.station.profile",
              "pyrt.station.recording", "pyrt.station.blackbox", "pyrt.station.replay",
              "pyrt.station.factory", "pyrt.station._urdf_sim", "pyrt.station._cell_world",
              "pyrt.scheduler.loop", "pyrt.scheduler.runner", "pyrt.scheduler.readyqueue",
              "pyrt.scheduler.rategroup", "pyrt.scheduler.task", "pyrt.scheduler.clock",
              "pyrt.scheduler._", "pyrt.scheduler.stats", "pyrt.scheduler.timinglog",
              "pyrt.scheduler.gcwatch", "pyrt.component")


class SnapshotError(ConfigError):
    """A state that cannot be snapshot (the message says which), or a snapshot that
    cannot be restored (damaged, of another station, of another format)."""


_MISSING = object()


#: How each class's values are encoded, by the package that counts as pyrt's.
_KINDS: dict[str, dict[type, str]] = {}
#: Per package: the encodings of values that cannot change (tuples and frozen
#: records of numbers, text, enums ...), by id, each with its value (held, so that
#: its id is not another's), and the frozen records' layouts.
_FROZEN: dict[str, dict[int, tuple[Any, Any]]] = {}
_RECORDS: dict[str, dict[type, _Layout]] = {}
#: The encodings of unchanging values kept, at most (all dropped when full).
_MAX_FROZEN = 4096
#: The kinds a plan encodes inline (:meth:`_Encoder.read_attributes`).
_FROZEN_KIND, _LIST_KIND, _CDATA_KIND, _OBJECT_KIND = "frozen", "list", "cdata", "object"
#: How each C memory met is copied (:func:`_copying`), by id.
_CDATA: dict[int, tuple[Any, Any, Any, int]] = {}


class _Skip(Exception):
    """Not state: a function, a view of another buffer, an object of the structure."""


@dataclass(frozen=True)
class Snapshot:
    """The controller's state before tick :attr:`tick` (see the module text)."""

    station: str
    tick: int = 0
    time_ns: int = 0
    inputs: tuple[int, ...] = ()
    outputs: tuple[int, ...] = ()
    loop: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    station_state: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    state: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    #: Why the station could not give its state ('' when it could).
    refused: str = ""

    def encode(self) -> bytes:
        """The snapshot as JSON (UTF-8)."""
        doc: dict[str, Any] = {"format": SNAPSHOT_FORMAT, "station": self.station}
        if self.refused:
            doc["refused"] = self.refused
        else:
            doc.update(tick=self.tick, time_ns=self.time_ns, inputs=list(self.inputs),
                       outputs=list(self.outputs), loop=self.loop,
                       station_state=self.station_state, state=self.state)
        return json.dumps(doc, separators=(",", ":"), default=_plain).encode("utf-8")

    @classmethod
    def decode(cls, data: bytes) -> Snapshot:
        """The snapshot ``data`` holds; SnapshotError if it is not one this pyrt reads."""
        try:
            doc = json.loads(data.decode("utf-8"))
        except (UnicodeDecodeError, ValueError) as exc:
            raise SnapshotError(f"the snapshot is damaged: not JSON ({exc})") from None
        if not isinstance(doc, dict):
            raise SnapshotError("the snapshot is damaged: not a JSON object")
        fmt = doc.get("format")
        if fmt != SNAPSHOT_FORMAT:
            raise SnapshotError(f"the snapshot's format is {str(fmt)[:40]!r}; this pyrt reads "
                                f"{SNAPSHOT_FORMAT!r}")
        station = doc.get("station")
        if not isinstance(station, str):
            raise SnapshotError("the snapshot is damaged: it names no station")
        if "refused" in doc:
            return cls(station, refused=str(doc["refused"]))
        try:
            tick, time_ns = doc["tick"], doc["time_ns"]
            inputs, outputs = doc["inputs"], doc["outputs"]
            loop, st, state = doc["loop"], doc["station_state"], doc["state"]
        except KeyError as exc:
            raise SnapshotError(f"the snapshot is damaged: it has no {exc.args[0]}") from None
        ints = [tick, time_ns, *inputs, *outputs] if isinstance(inputs, list) \
            and isinstance(outputs, list) else None
        if ints is None or not all(type(v) is int for v in ints) or tick < 0 \
                or not all(isinstance(m, dict) for m in (loop, st, state)):
            raise SnapshotError("the snapshot is damaged: its tick, time, inputs or outputs "
                                "are not integers")
        return cls(station, tick, time_ns, tuple(inputs), tuple(outputs), loop, st, state)


# -- values ------------------------------------------------------------------------------


def _roots(extra: str = "") -> set[str]:
    return {"pyrt", extra} - {""}


def _class_name(cls: type) -> str:
    return f"{cls.__module__}:{cls.__qualname__}"


def _structure(cls: type) -> bool:
    if any(k.__name__ == "Station" and k.__module__ == "pyrt.station.base" for k in cls.__mro__):
        return True  # a station (the components are walked, not their station)
    module = cls.__module__
    return any(module == p or module.startswith(p + ".") or (p.endswith("_")
               and module.startswith(p)) for p in _STRUCTURE)


_PLAIN = frozenset((int, float, str, bool, type(None)))
#: The lock types: a snapshot says a lock is there (a restored object gets a new one).
_LOCKS = (type(threading.Lock()), type(threading.RLock()))


#: What to do with an object's values: the places left out, and the places encoded
#: with their names and kinds.
_Plan = tuple[tuple[int, ...], tuple[tuple[int, str, str], ...]]


class _Encoder:
    def __init__(self, package: str):
        self.roots = _roots(package)
        self.seen: dict[int, str] = {}
        self.kinds = _KINDS.setdefault(package, {})
        #: Encodings of values that cannot change, by id (with the value, held).
        self.frozen = _FROZEN.setdefault(package, {})
        #: The frozen records' layouts (their fields).
        self.records = _RECORDS.setdefault(package, {})
        #: Values encoded so far that may change (objects, lists, arrays, C memory ...).
        self.changing = 0

    def _kind(self, cls: type) -> str:
        """How values of ``cls`` are encoded (decided once per class)."""
        if issubclass(cls, enum.Enum):
            kind = "enum" if cls.__module__.split(".")[0] in self.roots else "skip"
        elif issubclass(cls, np.generic):
            kind = "npscalar"
        elif issubclass(cls, bool | int | str | float):
            kind = "plain"
        elif issubclass(cls, list):
            kind = "list"
        elif issubclass(cls, tuple):
            kind = "skip" if hasattr(cls, "_fields") else "tuple"
        elif issubclass(cls, dict):
            kind = "dict"
        elif issubclass(cls, bytearray):
            kind = "bytearray"
        elif issubclass(cls, bytes):
            kind = "bytes"
        elif issubclass(cls, np.ndarray):
            kind = "ndarray"
        elif issubclass(cls, deque):
            kind = "deque"
        elif issubclass(cls, set | frozenset):
            kind = "set"
        elif cls.__name__.startswith("__CData") or cls.__name__ == "CData":
            kind = "cdata"
        elif cls is threading.Event:
            kind = "event"
        elif cls in _LOCKS:
            kind = "lock"
        elif issubclass(cls, FunctionType | MethodType | BuiltinFunctionType | type | ModuleType
                        | range | slice | memoryview) \
                or cls.__module__.split(".")[0] not in self.roots or _structure(cls):
            kind = "skip"
        elif dataclasses.is_dataclass(cls) and getattr(cls, "__dataclass_params__").frozen:  # noqa: B009
            kind = "record"
        else:
            kind = "object"
        self.kinds[cls] = kind
        return kind

    def value(self, v: Any, path: str) -> Any:
        cls = type(v)
        if cls in _PLAIN:
            return v
        kind = self.kinds.get(cls) or self._kind(cls)
        if kind == "object":
            self.changing += 1  # (a reference too: its path is this snapshot's)
            if id(v) in self.seen:
                return {"$r": self.seen[id(v)]}
            self.seen[id(v)] = path
            read = _read(v, cls)
            if read is None:
                attrs = getattr(v, "__dict__", None)
                if attrs is None:
                    attrs = _slot_attributes(v, cls)
                return {"$c": _class_name(cls), "$o": self.attributes(attrs, path)}
            layout, vals = read
            # its attributes as a dict when the snapshot is written (:func:`_later`)
            return _later(_object, layout.name, layout.names,
                          self.read_attributes(layout, vals, path))
        if kind == "list":
            self.changing += 1
            if _PLAIN.issuperset(map(type, v)):  # numbers and text: the list as it is
                return v.copy()
            return self.items(v, path)
        if kind == "tuple" or kind == "record":
            # a value that cannot change (a tuple, a frozen record) holding only such
            # values: encoded once while the same one is held (a constant's, a move's)
            held = self.frozen.get(id(v))
            if held is not None and held[0] is v:
                return held[1]
            changing = self.changing
            if kind == "tuple":
                if _PLAIN.issuperset(map(type, v)):
                    out: Any = {"$t": list(v)}
                else:
                    out = {"$t": self.items(v, path)}
            else:
                fields = self.records.get(cls)
                if fields is None:
                    fields = self.records[cls] = _Layout(cls, tuple(
                        f.name for f in dataclasses.fields(cls)))
                out = _later(_record, fields.name, fields.names,  # every field, or none
                             self.read_attributes(fields, fields.get(v), path, whole=True))
            if self.changing == changing:
                frozen = self.frozen
                if len(frozen) >= _MAX_FROZEN:
                    frozen.clear()
                frozen[id(v)] = (v, out)
            return out
        if kind == "plain":  # a subclass of a plain type
            return v
        if kind == "skip":
            raise _Skip
        if kind == "enum":
            return {"$e": _class_name(cls), "v": v.name}
        if kind == "npscalar":
            return {"$n": [v.dtype.str, v.tobytes().hex()]}
        if kind == "bytes":
            return {"$b": v.hex()}
        self.changing += 1  # from here on, values that may change in place
        if kind == "cdata":
            return self._cdata(v)
        if kind == "ndarray":
            writeable = v.flags.writeable
            if v.dtype.hasobject or (not writeable and v.base is not None):
                raise _Skip  # a read-only view of another array: that one is state
            out = {"$a": [v.dtype.str, list(v.shape), v.tobytes().hex()]}
            if not writeable:
                out["ro"] = True  # a read-only value (a transform's) stays read-only
            first = self.seen.get(id(v))
            if first is not None:  # one array held twice: "is" the path it was given at
                out["is"] = first  # (its data too, should that place not be restored)
            else:
                self.seen[id(v)] = path
            return out
        if kind == "dict":
            return {"$d": self.pairs(v, path)}
        if kind == "bytearray":
            return {"$ba": v.hex()}
        if kind == "deque":
            return {"$q": self.items(v, path)}
        if kind == "set":
            return {"$s": self.members(v, path)}
        if kind == "event":
            return {"$ev": v.is_set()}
        if kind == "lock":
            return {"$lk": 0}
        raise _Skip  # not a kind of pyrt's state

    def read_attributes(self, layout: _Layout, vals: tuple, path: str,
                        whole: bool = False) -> list[Any]:
        """The values of an object's attributes, read by its ``layout`` as ``vals``:
        plain ones as they are (the list copied by one C call), the others encoded,
        the structure's :data:`_GONE` (``whole``: none may be, else _Skip); what to
        do at each place is decided once per classes of the values."""
        kinds = tuple(map(type, vals))
        plan = layout.plans.get(kinds)
        if plan is None:
            plan = layout.plans[kinds] = self._plan(layout.names, kinds)
        out = list(vals)
        drop, encode = plan
        if drop:
            if whole:
                raise _Skip
            for i in drop:
                out[i] = _GONE
        frozen = self.frozen
        for i, name, kind in encode:
            # inline, the common values: one that cannot change and was encoded
            # before, a list of numbers, C memory
            x = vals[i]
            try:
                if kind is _FROZEN_KIND:
                    held = frozen.get(id(x))
                    if held is not None and held[0] is x:
                        out[i] = held[1]
                        continue
                elif kind is _LIST_KIND:
                    if _PLAIN.issuperset(map(type, x)):
                        self.changing += 1
                        out[i] = x.copy()
                        continue
                elif kind is _CDATA_KIND:
                    self.changing += 1
                    out[i] = self._cdata(x)
                    continue
                elif kind is _OBJECT_KIND:
                    first = self.seen.get(id(x))
                    if first is not None:  # given before: a reference to it
                        self.changing += 1
                        out[i] = {"$r": first}
                        continue
                out[i] = self.value(x, f"{path}.{name}")
            except _Skip:
                if whole:
                    raise
                out[i] = _GONE
        return out

    def items(self, v: list | tuple, path: str) -> list[Any]:
        """The items of a list or a tuple, encoded (those that cannot change and were
        encoded before, inline)."""
        out = []
        frozen = self.frozen
        for i, x in enumerate(v):
            if type(x) in _PLAIN:
                out.append(x)
                continue
            held = frozen.get(id(x))
            if held is not None and held[0] is x:
                out.append(held[1])
            else:
                out.append(self.value(x, f"{path}[{i}]"))
        return out

    def pairs(self, v: dict, path: str) -> list[list[Any]]:
        """A dict's items, keys and values encoded."""
        return [[self.value(k, f"{path}<{i}"), self.value(x, f"{path}{{{i}}}")]
                for i, (k, x) in enumerate(v.items())]

    def members(self, v: set | frozenset, path: str) -> list[Any]:
        """A set's members, encoded in the order of their reprs."""
        return [self.value(x, path) for x in sorted(v, key=repr)]

    def _plan(self, names: tuple[str, ...], kinds: tuple[type, ...]) -> _Plan:
        """For values of ``kinds`` at ``names``: the places left out (structure: a
        method, a board) and the places encoded (neither plain nor structure), each
        with its kind (:data:`_FROZEN_KIND`, :data:`_LIST_KIND`, :data:`_CDATA_KIND`,
        :data:`_OBJECT_KIND` or another)."""
        drop: list[int] = []
        encode: list[tuple[int, str, str]] = []
        for i, (name, cls) in enumerate(zip(names, kinds, strict=True)):
            if cls in _PLAIN:
                continue
            kind = self.kinds.get(cls) or self._kind(cls)
            if kind == "skip":
                drop.append(i)
            elif kind != "plain":
                encode.append((i, name, _FROZEN_KIND if kind in ("tuple", "record")
                               else _LIST_KIND if kind == "list"
                               else _CDATA_KIND if kind == "cdata"
                               else _OBJECT_KIND if kind == "object" else kind))
        return tuple(drop), tuple(encode)

    def attributes(self, attrs: Mapping[str, Any], path: str) -> dict[str, Any]:
        out = {}
        plain = _PLAIN
        kinds = self.kinds
        for key, x in list(attrs.items()):
            cls = type(x)
            if cls in plain:
                out[key] = x
                continue
            if kinds.get(cls) == "skip":  # structure (a method, a board): not state
                continue
            try:
                out[key] = self.value(x, f"{path}.{key}")
            except _Skip:
                continue
        return out

    @staticmethod
    def _cdata(v: Any) -> Any:
        # memory a kernel's object owns: its numbers (arrays, the scalar fields of
        # its structs); pointers are structure, bound once when it was built.  The
        # memory is copied now (the state at this tick), its numbers read out of
        # the copy when the snapshot is encoded (:func:`_c_numbers`).  How to copy
        # it is found once per object (held with it, so that its id is not another's)
        how = _CDATA.get(id(v))
        if how is None or how[0] is not v:
            how = _copying(v)
            if len(_CDATA) >= _MAX_FROZEN:
                _CDATA.clear()
            _CDATA[id(v)] = how
        _v, ctype, length, nbytes = how
        if ctype is None:
            raise _Skip
        copy = _newp(ctype, length)
        _memmove(copy, v, nbytes)
        return _later(_c_numbers, copy, ctype)


def _copying(v: Any) -> tuple[Any, Any, Any, int]:
    """How C memory ``v`` is copied: ``(v, its type, newp's length, bytes)``; its
    type None when it is not memory of its own (a view, a pointer into another's)."""
    if "owning" not in repr(v):
        return v, None, None, 0
    ctype = _cffi_typeof(v)
    if ctype.kind == "pointer":
        return v, ctype, None, _sizeof(ctype.item)
    if ctype.kind == "array":
        return v, ctype, len(v) if ctype.length is None else None, _sizeof(v)
    return v, None, None, 0


def _c_numbers(copy: Any, ctype: Any) -> dict[str, Any]:
    """C memory a kernel owns, copied when the snapshot was taken (one ``memmove``
    in the loop thread), as its numbers (``{"$cd": ...}``, :func:`_cd_get`): read
    out when the snapshot is written, in the thread that writes the black box."""
    if ctype.kind == "pointer":
        return {"$cd": _cd_get(copy[0], ctype.item)}
    return {"$cd": _cd_get(copy, ctype)}


#: A value left out of an object's attributes (:meth:`_Encoder.read_attributes`).
_GONE: Any = object()
#: ``_later(fn, *args)``: a part of a snapshot encoded when it is written, by
#: ``fn(*args)`` (one C call to make in the loop thread).
_later = functools.partial


def _object(name: str, names: tuple[str, ...], vals: list[Any]) -> dict[str, Any]:
    """An object's encoding, from its class's name and its attributes' names and values."""
    return {"$c": name, "$o": {n: x for n, x in zip(names, vals, strict=True) if x is not _GONE}}


def _record(name: str, names: tuple[str, ...], vals: list[Any]) -> dict[str, Any]:
    """A frozen record's encoding, from its class's name and its fields."""
    return {"$dc": name, "f": dict(zip(names, vals, strict=True))}


def _without(refs: list[Any], cls: type) -> list[Any]:
    return [r for r in refs if r is not cls]


def _slot_attributes(v: Any, cls: type) -> dict[str, Any]:
    return {a: getattr(v, a) for a in _slots(cls) if hasattr(v, a)}


def _plain(v: Any) -> Any:
    """``json``'s ``default``: a part encoded when written (:data:`_later`: C memory,
    an object's attributes) as its encoding."""
    if type(v) is _later:
        return v()
    raise TypeError(f"a snapshot holds a {type(v).__name__}, which has no JSON form")


#: Per class: the names its code reads or writes on objects (its methods' and
#: their nested functions' ``co_names``, its fields and annotations), the
#: candidates for its instances' attributes; None: a class whose instances are
#: read through ``__dict__`` (it has ``__getattr__``).
_NAMES: dict[type, tuple[str, ...] | None] = {}


def _code_names(code: CodeType, out: set[str]) -> None:
    out.update(code.co_names)
    for c in code.co_consts:
        if isinstance(c, CodeType):
            _code_names(c, out)


def _candidates(cls: type) -> tuple[str, ...] | None:
    names = _NAMES.get(cls, ())
    if names != ():
        return names
    found: set[str] = set()
    getattr_hook = False
    for k in cls.__mro__:
        if k is object:
            continue
        if "__getattr__" in k.__dict__ or "__getattribute__" in k.__dict__:
            getattr_hook = True
        found.update(getattr(k, "__annotations__", {}) if "__annotations__" in k.__dict__
                     else ())
        for x in k.__dict__.values():
            x = getattr(x, "__func__", x)  # a static or class method
            for f in (x, getattr(x, "fget", None), getattr(x, "fset", None)):
                code = getattr(f, "__code__", None)
                if isinstance(code, CodeType):
                    _code_names(code, found)
    if dataclasses.is_dataclass(cls):
        found.update(f.name for f in dataclasses.fields(cls))
    # the names the class itself has (its methods, properties, class attributes)
    # are not among them: a class attribute's name is given only to a value no
    # other name has claimed (:func:`_instance_attributes`)
    mine = {n for k in cls.__mro__ for n in k.__dict__}
    result = None if getattr_hook else tuple(sorted(n for n in found if n not in mine))
    _NAMES[cls] = result
    return result


def _class_defaults(cls: type) -> list[str]:
    """The names of ``cls``'s class attributes that are plain values (not methods,
    properties or other descriptors), nearest class first."""
    out: list[str] = []
    for k in cls.__mro__:
        if k is object:
            continue
        for n, d in k.__dict__.items():
            t = type(d)
            if not n.startswith("__") and n not in out \
                    and not (hasattr(t, "__get__") or hasattr(t, "__set__")):
                out.append(n)
    return out


def _instance_attributes(v: Any, cls: type) -> dict[str, Any] | None:
    """The attributes of ``v`` as ``v.__dict__`` has them (the same names and values),
    read without asking for ``__dict__``: on CPython 3.11 and 3.12 an object keeps its
    attributes in an array of values shared with its class's keys until its
    ``__dict__`` is asked for, which makes a dict of them for good; from then on
    every attribute of the object is a dict lookup (the manipulator's tick about
    5 % slower after its first snapshot).  The values are the object's references
    (``gc.get_referents``: its values, in the order their names were first set, and
    its class); each is given the name among the class's code's names that reads
    it from ``v`` (and, once for a class whose objects are given attributes by
    other code, among every name pyrt's code uses, the names found kept for the
    class).  None (ask ``__dict__``) when that does not account for every value."""
    if not cls.__dictoffset__:
        return None  # no dict of attributes: its slots are read
    refs = [r for r in gc.get_referents(v) if r is not cls]
    whole = len(refs) == 1 and type(refs[0]) is dict
    if whole and cls in _DICT_BACKED:
        return None  # its attributes are a dict already (as its class's were)
    learned = _LEARNED.get(cls)
    if learned is not None and len(learned) == len(refs):
        # the names its last object had, in its order: each reads the value there
        out = {}
        for name, r in zip(learned, refs, strict=True):
            if getattr(v, name, _MISSING) is not r:
                break
            out[name] = r
        else:
            return out
    names = _candidates(cls)
    if names is None:
        return None
    left: dict[int, list[int]] = {}
    for i, r in enumerate(refs):
        left.setdefault(id(r), []).append(i)
    got: list[tuple[int, str, Any]] = []
    _claim(v, cls, names, left, got)
    if len(got) != len(refs):
        defaults = _class_defaults(cls)
        _claim(v, cls, defaults, left, got)  # an attribute that shadows a class's
        if len(got) != len(refs):
            if whole:
                _DICT_BACKED.add(cls)
                return None  # its attributes are a dict already
            if cls in _LOOKED_FURTHER:
                return None
            _LOOKED_FURTHER.add(cls)
            for i in range(len(got) - 1, -1, -1):  # not these: look further first
                if got[i][1] in defaults:
                    left[id(got[i][2])].insert(0, got[i][0])
                    del got[i]
            for where in left.values():
                where.sort()
            known = set(names) | set(defaults)
            found = len(got)
            _claim(v, cls, [n for n in _all_names() if n not in known], left, got)
            _NAMES[cls] = names + tuple(sorted(name for _i, name, _x in got[found:]))
            _claim(v, cls, defaults, left, got)
            if len(got) != len(refs):
                return None
    got.sort()
    out = {name: x for _i, name, x in got}
    _LEARNED[cls] = tuple(out)
    return out


def _claim(v: Any, cls: type, names: Sequence[str], left: dict[int, list[int]],
           got: list[tuple[int, str, Any]]) -> None:
    """Give each of ``names`` that reads one of ``v``'s values still unnamed (``left``:
    the positions of each value, by id) that value's first position (into ``got``)."""
    mro = cls.__mro__
    for name in names:
        descriptor = False
        for k in mro:  # a property or a method is not read (a property may compute)
            d = k.__dict__.get(name, _MISSING)
            if d is not _MISSING:
                t = type(d)
                descriptor = hasattr(t, "__get__") or hasattr(t, "__set__")
                break
        if descriptor:
            continue
        try:
            x = getattr(v, name)
        except AttributeError:
            continue
        where = left.get(id(x))
        if where:
            got.append((where.pop(0), name, x))


class _Layout:
    """How one class's objects with the same attributes (names, in their order) are
    read: one ``attrgetter`` call gives every value, checked against the object's
    own (``gc.get_referents``) by identity; and, per the classes of those values,
    what a snapshot does with each (:meth:`_Encoder.read_attributes`)."""

    __slots__ = ("get", "n", "name", "names", "plans")

    def __init__(self, cls: type, names: tuple[str, ...]):
        self.names = names
        self.n = len(names)
        self.name = _class_name(cls)
        if not names:
            self.get: Callable[[Any], tuple] = lambda v: ()
        elif len(names) == 1:
            one = operator.attrgetter(names[0])
            self.get = lambda v: (one(v),)
        else:
            self.get = operator.attrgetter(*names)
        #: Per classes of the values: the places left out and the places encoded.
        self.plans: dict[tuple[type, ...], _Plan] = {}


#: Per class: the layouts its objects were read by, the one that fitted last first.
_LAYOUTS: dict[type, list[_Layout]] = {}
#: The layouts a class keeps, at most (its objects' attributes set in other orders).
_MAX_LAYOUTS = 8


def _read(v: Any, cls: type) -> tuple[_Layout, tuple] | None:
    """``v``'s attributes as one of its class's layouts reads them (the names and
    values of ``v.__dict__``, without asking for it: :func:`_instance_attributes`),
    or None: read them through ``__dict__`` (or its slots)."""
    if not cls.__dictoffset__:
        return None
    layouts = _LAYOUTS.get(cls)
    if layouts is not None:
        refs = gc.get_referents(v)
        if refs and refs[-1] is cls:
            del refs[-1]
        else:
            refs = _without(refs, cls)
        n = len(refs)
        for k, layout in enumerate(layouts):
            if layout.n != n:
                continue
            try:
                vals = layout.get(v)
                # one C call: each value is the object's own, in its place (an
                # identical one compares equal at once; where two places hold
                # equal values the names read the object's own all the same)
                same = vals == tuple(refs)
            except AttributeError:
                continue
            except Exception:  # an array's elementwise ==: not in its place
                same = False
            if not same:
                # the same names in another order?  Two attributes that held one
                # value (two zeros) when the order was learned can only be told
                # apart by an object where they differ: this one, if it fits
                names = _reordered(layout.names, vals, refs)
                if names is None:
                    continue
                layout = layouts[k] = _Layout(cls, names)
                vals = tuple(refs)
            if k:
                layouts.insert(0, layouts.pop(k))
            return layout, vals
    attrs = _instance_attributes(v, cls)
    if attrs is None:
        return None
    layout = _Layout(cls, tuple(attrs))
    layouts = _LAYOUTS.setdefault(cls, [])
    layouts.insert(0, layout)
    del layouts[_MAX_LAYOUTS:]
    return layout, tuple(attrs.values())


def _reordered(names: tuple[str, ...], vals: tuple, refs: list[Any]) -> tuple[str, ...] | None:
    """``names`` (whose values are ``vals``) in the order of the object's own values
    ``refs``, a name that held the same value as another keeping its place before
    that one where this object cannot tell them apart; None if they are not the
    same values."""
    by_value: dict[int, list[str]] = {}
    for name, x in zip(names, vals, strict=True):
        by_value.setdefault(id(x), []).append(name)
    out = []
    for r in refs:
        same = by_value.get(id(r))
        if not same:
            return None
        out.append(same.pop(0))
    return tuple(out)


_ALL_NAMES: list[str] = []
#: The classes of objects whose attributes were found in a dict (asked for before).
_DICT_BACKED: set[type] = set()
#: Per class: the names of the last of its objects read, in the order of its values.
_LEARNED: dict[type, tuple[str, ...]] = {}
#: The classes whose objects' names were looked for among :func:`_all_names` (once).
_LOOKED_FURTHER: set[type] = set()


def _all_names() -> list[str]:
    """Every name the code of pyrt's modules (loaded now) reads or writes on objects."""
    if not _ALL_NAMES:
        found: set[str] = set()
        for mod_name, mod in list(sys.modules.items()):
            if mod_name.split(".")[0] != "pyrt" or mod is None:
                continue
            for x in list(vars(mod).values()):
                for f in ([x] if not isinstance(x, type) else
                          [getattr(y, "__func__", y) for y in x.__dict__.values()]):
                    for g in (f, getattr(f, "fget", None), getattr(f, "fset", None)):
                        code = getattr(g, "__code__", None)
                        if isinstance(code, CodeType):
                            _code_names(code, found)
        _ALL_NAMES.extend(sorted(n for n in found if not n.startswith("__")))
    return _ALL_NAMES


def _slots(cls: type) -> tuple[str, ...]:
    """The attributes a class with ``__slots__`` (and no ``__dict__``) holds."""
    names: list[str] = []
    for k in cls.__mro__:
        slots = k.__dict__.get("__slots__", ())
        names += [slots] if isinstance(slots, str) else [n for n in slots if n != "__weakref__"]
    return tuple(names)


_cffi_typeof = _cffi_backend.typeof
_newp = _cffi_backend.newp
_memmove = _cffi_backend.memmove
_sizeof = _cffi_backend.sizeof


def _cd_get(v: Any, ctype: Any) -> Any:
    """The numbers in C memory ``v`` of type ``ctype``: a number, a list (an array),
    a dict (a struct's fields that are not pointers); pointers: None."""
    kind = ctype.kind
    if kind == "primitive":
        return v
    if kind == "array":
        if ctype.item.kind == "primitive":
            return list(v)
        return [_cd_get(v[i], ctype.item) for i in range(len(v))]
    if kind == "struct":
        return {name: _cd_get(getattr(v, name), f.type) for name, f in ctype.fields
                if f.type.kind in ("primitive", "array", "struct")}
    return None


def _cd_put(v: Any, ctype: Any, data: Any) -> None:
    """Write :func:`_cd_get`'s ``data`` back into C memory ``v`` (arrays and structs)."""
    kind = ctype.kind
    if kind == "array":
        item = ctype.item
        if len(data) != len(v):
            raise SnapshotError("the snapshot's C array is not the kernel's size")
        for i, x in enumerate(data):
            if item.kind == "primitive":
                v[i] = float(x["$fl"]) if isinstance(x, dict) else x
            else:
                _cd_put(v[i], item, x)
    elif kind == "struct":
        fields = dict(ctype.fields)
        for name, x in data.items():
            f = fields[name].type
            if f.kind == "primitive":
                setattr(v, name, float(x["$fl"]) if isinstance(x, dict) else x)
            else:
                _cd_put(getattr(v, name), f, x)


class _Decoder:
    def __init__(self, package: str):
        self.roots = _roots(package)
        self.seen: dict[str, Any] = {}

    def _class(self, name: Any) -> type:
        module, _, qual = str(name).partition(":")
        if module.split(".")[0] not in self.roots:
            raise SnapshotError(f"the snapshot names a class of {module[:60]!r}, not of pyrt")
        try:
            obj: Any = importlib.import_module(module)
            for part in qual.split("."):
                obj = getattr(obj, part)
        except (ImportError, AttributeError):
            raise SnapshotError(f"the snapshot names a class {str(name)[:80]!r} this pyrt "
                                "does not have") from None
        if not isinstance(obj, type):
            raise SnapshotError(f"the snapshot names {str(name)[:80]!r}, which is not a class")
        return obj

    def value(self, v: Any, cur: Any, path: str) -> Any:
        if v is None or isinstance(v, bool | int | str | float):
            return v
        if isinstance(v, list):
            items = [self.value(x, cur[i] if isinstance(cur, list) and i < len(cur) else None,
                            f"{path}[{i}]") for i, x in enumerate(v)]
            if isinstance(cur, list):
                cur[:] = items
                return cur
            return items
        if type(v) is _later:  # restored as it was taken (not read back)
            v = v()
        if not isinstance(v, dict) or not v:
            raise SnapshotError(f"the snapshot is damaged at {path}: {str(v)[:40]!r}")
        tag = next(iter(v))
        body = v[tag]
        try:
            return self._tagged(tag, body, v, cur, path)
        except (ValueError, TypeError, KeyError, IndexError) as exc:
            raise SnapshotError(f"the snapshot is damaged at {path}: {exc}") from None

    def _tagged(self, tag: str, body: Any, v: dict, cur: Any, path: str) -> Any:
        if tag == "$fl":
            return float(body)
        if tag == "$t":
            return tuple(self.value(x, cur[i] if isinstance(cur, tuple) and i < len(cur)
                                    else None, f"{path}[{i}]") for i, x in enumerate(body))
        if tag == "$d":
            old = cur if isinstance(cur, dict) else {}
            pairs = []
            for i, (k, x) in enumerate(body):
                key = self.value(k, None, f"{path}<{i}")
                pairs.append((key, self.value(x, old.get(key), f"{path}{{{i}}}")))
            if isinstance(cur, dict):
                cur.clear()
                cur.update(pairs)
                return cur
            return dict(pairs)
        if tag in ("$b", "$ba"):
            data = bytes.fromhex(body)
            if tag == "$b":
                return data
            if isinstance(cur, bytearray):
                if len(cur) != len(data):
                    raise SnapshotError(f"the snapshot's {path} is {len(data)} bytes, the "
                                        f"station's {len(cur)}")
                cur[:] = data
                return cur
            return bytearray(data)
        if tag == "$a":
            same = self.seen.get(v["is"]) if "is" in v else None
            if isinstance(same, np.ndarray):
                return _same_array(same, cur)
            got = self._array(body, v, cur, path)
            self.seen[path] = got
            return got
        if tag == "$n":
            return np.frombuffer(bytes.fromhex(body[1]), dtype=np.dtype(body[0]))[0]
        if tag == "$q":
            items = [self.value(x, None, f"{path}[{i}]") for i, x in enumerate(body)]
            if isinstance(cur, deque):
                cur.clear()
                cur.extend(items)
                return cur
            return deque(items)
        if tag == "$s":
            return {self.value(x, None, path) for x in body}
        if tag == "$cd":
            if cur is None or not type(cur).__name__.startswith("__CData"):
                return cur  # a workspace not built yet (made when first used): nothing to keep
            ctype = _cffi_typeof(cur)
            if ctype.kind == "pointer":
                _cd_put(cur[0], ctype.item, body)
            else:
                _cd_put(cur, ctype, body)
            return cur
        if tag == "$ev":  # an event: set or not (a move's reached)
            event = cur if isinstance(cur, threading.Event) else threading.Event()
            if body:
                event.set()
            else:
                event.clear()
            return event
        if tag == "$lk":  # a lock: the station's own, or a new one (free)
            return cur if type(cur) in _LOCKS else threading.Lock()
        if tag == "$r":
            if body not in self.seen:
                raise SnapshotError(f"the snapshot is damaged at {path}: it refers to "
                                    f"{str(body)[:60]!r}, which it did not give")
            return self.seen[body]
        if tag == "$e":
            cls = self._class(body)
            if not issubclass(cls, enum.Enum) or v["v"] not in cls.__members__:
                raise SnapshotError(f"the snapshot is damaged at {path}: {body[:60]!r} has "
                                    f"no member {str(v['v'])[:40]!r}")
            return cls[v["v"]]
        if tag == "$dc":
            cls = self._class(body)
            if not dataclasses.is_dataclass(cls):
                raise SnapshotError(f"the snapshot names {body[:80]!r} as a record; it is not")
            obj = object.__new__(cls)
            for name, x in v["f"].items():
                object.__setattr__(obj, name, self.value(x, None, f"{path}.{name}"))
            return obj
        if tag == "$c":
            if cur is None or _class_name(type(cur)) != body:
                made: Any = self._class(body)  # an object the station has not (a motion)
                cur = made.__new__(made)
                _defaults(cur)
            self.seen[path] = cur
            self.attributes(cur, v["$o"], path)
            return cur
        raise SnapshotError(f"the snapshot is damaged at {path}: unknown kind {tag[:20]!r}")

    @staticmethod
    def _array(body: Any, v: dict, cur: Any, path: str) -> np.ndarray:
        """A ``$a`` value: written into the station's own array in place (a
        read-only one replaced when it differs), or a new one."""
        dtype, shape, data = body
        arr = np.frombuffer(bytes.fromhex(data), dtype=np.dtype(dtype)).reshape(shape)
        if isinstance(cur, np.ndarray):
            if cur.shape != arr.shape or cur.dtype != arr.dtype:
                raise SnapshotError(f"the snapshot's {path} is a {arr.dtype} array of "
                                    f"shape {arr.shape}, the station's {cur.dtype} "
                                    f"{cur.shape}")
            if cur.flags.writeable:
                cur[...] = arr
                return cur
            if np.array_equal(cur, arr, equal_nan=cur.dtype.kind in "fc"):
                return cur
            new = arr.copy()  # a read-only value (a transform's): replaced, not changed
            new.flags.writeable = False
            return new
        new = arr.copy()
        if v.get("ro"):
            new.flags.writeable = False
        return new

    def attributes(self, obj: Any, state: Mapping[str, Any], path: str) -> None:
        if not isinstance(state, Mapping):
            raise SnapshotError(f"the snapshot is damaged at {path}: not an object's state")
        attrs = getattr(obj, "__dict__", None)
        slots = _slots(type(obj)) if attrs is None else ()
        for key, x in state.items():
            if attrs is not None:
                old = attrs.get(key, _MISSING)
            elif key in slots:
                old = getattr(obj, key, _MISSING)
            else:
                raise SnapshotError(f"the snapshot is damaged at {path}: a "
                                    f"{type(obj).__name__} has no {str(key)[:40]!r}")
            new = self.value(x, None if old is _MISSING else old, f"{path}.{key}")
            if old is not new:
                if attrs is not None:
                    attrs[key] = new
                else:
                    setattr(obj, key, new)


def _same_array(same: np.ndarray, cur: Any) -> np.ndarray:
    """An array held twice, restored at its first place as ``same``: the station's
    own array ``cur`` here keeps its identity (a kernel may hold it) and takes the
    values; without one, ``same`` itself."""
    if isinstance(cur, np.ndarray) and cur is not same and cur.flags.writeable \
            and cur.shape == same.shape and cur.dtype == same.dtype:
        cur[...] = same
        return cur
    return same


def _defaults(obj: Any) -> None:
    """A dataclass object made for a snapshot: its fields' defaults first (what the
    snapshot does not carry, such as a move's reached event, is made as its class
    makes it; the snapshot's values then replace the rest)."""
    if not dataclasses.is_dataclass(obj):
        return
    for f in dataclasses.fields(obj):
        if f.default is not dataclasses.MISSING:
            value = f.default
        elif f.default_factory is not dataclasses.MISSING:
            value = f.default_factory()
        else:
            continue
        object.__setattr__(obj, f.name, value)


def state_of(objects: Mapping[str, Any], package: str = "") -> dict[str, Any]:
    """The state of ``objects`` (name -> object, each walked with every object of pyrt
    it holds: attributes that are numbers, text, containers, arrays, records), as
    JSON-able data whose costlier parts (C memory, the dicts of objects'
    attributes) are made only when it is written (:meth:`Snapshot.encode`,
    :func:`plain_state`): the loop thread only copies what can change.
    ``package``: a package whose classes count as pyrt's (a station's own).
    Functions, views, the boards, the world, the loop and the station are
    structure and left out."""
    enc = _Encoder(package)
    out: dict[str, Any] = {}
    for name, obj in objects.items():
        try:
            out[name] = enc.value(obj, name)
        except _Skip:
            raise SnapshotError(f"cannot snapshot: {name} is a {type(obj).__name__}, "
                                "not state") from None
    return out


def plain_state(state: Any) -> Any:
    """``state`` (of :func:`state_of`, whose parts are encoded only when written) as
    the plain JSON data a black box holds and a replay reads back."""
    return json.loads(json.dumps(state, default=_plain))


def restore_into(objects: Mapping[str, Any], state: Mapping[str, Any],
                 package: str = "") -> None:
    """Put ``state`` (:func:`state_of` of objects built the same way) back into
    ``objects``, in place: lists, arrays and bytearrays keep their identity (views
    and C kernels that share them see the restored values)."""
    dec = _Decoder(package)
    for name, obj in objects.items():
        if name not in state:
            raise SnapshotError(f"the snapshot has no state of {name}")
        got = dec.value(state[name], obj, name)
        if got is not obj:
            raise SnapshotError(f"the snapshot's {name} is not the station's ({type(got).__name__} "
                                f"for a {type(obj).__name__})")


# -- the loop's and the station's own ---------------------------------------------------


def _loop_state(station: Station) -> dict[str, Any]:
    loop = station.loop
    if loop.jobs:
        raise SnapshotError(f"cannot snapshot: the foreground job {loop.jobs[0].name} is "
                            "running (its place in its sequence is not state pyrt can save)")
    return loop.snapshot_state()


def _restore_loop(station: Station, state: Mapping[str, Any]) -> None:
    loop = station.loop
    groups, queues = state["groups"], state["queues"]
    if [g[0] for g in groups] != [g.name for g in loop.rate_groups] \
            or [q[0] for q in queues] != [q.name for q in loop.queues]:
        raise SnapshotError("the snapshot's rate groups and ready queues are not the station's "
                            f"({', '.join(str(q[0]) for q in queues)} against "
                            f"{', '.join(q.name for q in loop.queues)})")
    try:
        loop.restore_state(state)
    except ValueError as exc:
        raise SnapshotError(f"the snapshot does not fit the station's loop: {exc}") from None


_EVENTS = ("_moving", "_move_seq", "moves_this_period")


def _station_state(station: Station) -> dict[str, Any]:
    enc = _Encoder(type(station).__module__.split(".")[0])
    return {
        "robots": [[r.name, enc.value(r.fault, "fault"), r.moving] for r in station.robots],
        "events": [getattr(station, a) for a in _EVENTS],
        "motion": [enc.value(m, f"motion[{i}]") for i, m in enumerate(station.motion._q)],
    }


def _restore_station(station: Station, state: Mapping[str, Any]) -> None:
    dec = _Decoder(type(station).__module__.split(".")[0])
    robots = station.robots
    if [r[0] for r in state["robots"]] != [r.name for r in robots]:
        raise SnapshotError("the snapshot's robots are not the station's")
    for r, (_name, fault, moving) in zip(robots, state["robots"], strict=True):
        r.fault = dec.value(fault, None, "fault")
        r.moving = bool(moving)
    for a, v in zip(_EVENTS, state["events"], strict=True):
        setattr(station, a, v)
    queue = station.motion._q
    queue.clear()
    queue.extend(dec.value(m, None, f"motion[{i}]") for i, m in enumerate(state["motion"]))


def take_snapshot(station: Station, inputs: list[int], outputs: list[int]) -> Snapshot:
    """The station's state now (the loop thread, at the end of a tick: the state
    before the next), with the image's ``inputs`` and ``outputs``; a snapshot
    that says why when the station cannot give it."""
    try:
        loop = _loop_state(station)
        own = station.snapshot_state()
        common = _station_state(station)
    except SnapshotError as exc:
        return Snapshot(station.name, refused=str(exc))
    except _Skip:
        return Snapshot(station.name, refused="cannot snapshot: a robot's fault or a queued "
                                              "motion is not state pyrt can save")
    except Exception as exc:  # a hook that fails never fails the loop: the box says why
        return Snapshot(station.name, refused=f"cannot snapshot: {type(exc).__name__}: {exc}")
    return Snapshot(station.name, loop["tick"], station.loop.now_ns, tuple(inputs),
                    tuple(outputs), loop, common, own)


def restore_snapshot(station: Station, snap: Snapshot) -> None:
    """Put ``snap`` back into ``station`` (built as the run's was, not yet run);
    SnapshotError naming what does not fit (or the station's own refusal)."""
    if snap.refused:
        raise SnapshotError(snap.refused)
    if snap.station != station.name:
        raise SnapshotError(f"the snapshot is of station {snap.station!r}, not {station.name!r}")
    try:
        # the station's hook sees the state as a replay reads it from a black box
        # (a snapshot taken in this process holds parts encoded when written)
        station.restore_state(plain_state(dict(snap.state)))
        _restore_station(station, snap.station_state)
        _restore_loop(station, snap.loop)
    except SnapshotError:
        raise
    except Exception as exc:  # what does not fit the station, said in one line
        raise SnapshotError(f"the snapshot does not fit the station: {type(exc).__name__}: "
                            f"{exc}") from None


def compress_snapshot(snap: Snapshot) -> bytes:
    """The snapshot as an ``S`` frame holds it: its JSON, zlib-compressed."""
    return zlib.compress(snap.encode(), 6)


def decompress_snapshot(data: bytes) -> Snapshot:
    """The snapshot of an ``S`` frame; SnapshotError if it is damaged."""
    try:
        raw = zlib.decompress(data)
    except zlib.error as exc:
        raise SnapshotError(f"the snapshot is damaged: it does not decompress ({exc})") from None
    return Snapshot.decode(raw)

