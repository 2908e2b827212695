"""Runs and scope frames as MCAP files (needs the ``mcap`` library: ``pyrt[mcap]``).

MCAP is the container ros2 bag writes by default, and Foxglove, PlotJuggler
and rerun open it.  pyrt writes every message as JSON (message encoding
``json``), each channel with a JSON schema (schema encoding ``jsonschema``)
that names its fields and their units; log and publish times are the loop's
clock, in ns, as the journal and the scope record them.

A journal (``--journal FILE``, or a black box ``.pj``), by
:func:`export_journal`:

* ``/inputs/BOARD``: one message a tick, every input register of the board
  (``tio10``, ``gripper`` ...), as the tick's read phase brought it in;
* ``/outputs/BOARD``: one message a tick, every output register of the board
  after the tick's write phase;
* ``/writes``: one message per output written (register, value, the task
  that wrote it), in the order written;
* ``/ticks``: one message a tick (index, lateness, deadlines missed before it);
* ``/commands``: one per request applied (its text and source); ``/faults``:
  one per fault (its id and message); ``/events``: any other event;
  ``/gaps``: stretches the journal does not hold (at the time of the tick
  before them);
* ``/joint_states``: for a station whose root declares its joints
  (:attr:`pyrt.Component.joint_states`), one ``sensor_msgs/msg/JointState``
  a tick (SI units), sampled from a replay of the journal (the caller's:
  :class:`JointSamples`); and ``/robot_description`` (the URDF, once);
* metadata ``pyrt`` (station, tick, version, factory, ...), and the run's
  databases as attachments.

A scope frame, by :func:`save_frame_mcap` (``scope save FILE.mcap``): one
channel per object (``/scope/prototype`` with fields ``x``, ``y`` ...; a
signal named without its object on ``/scope``), one message per sample.

Files are written whole to a temporary file and renamed (atomic).
"""

from __future__ import annotations

import io
import json
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pyrt._version import __version__
from pyrt.errors import CommandError
from pyrt.fileio import atomic_write
from pyrt.journal import Gap, JournalReader, Tick
from pyrt.scope.joints import (
    JOINT_STATE_SCHEMA,
    JOINT_STATE_SCHEMA_NAME,
    ROBOT_DESCRIPTION_SCHEMA,
    JointStates,
    joint_state_json,
    si_factor,
)
from pyrt.scope.scope import Frame

__all__ = ["Exported", "JointSamples", "JsonMcap", "export_journal", "require_mcap",
           "save_frame_mcap"]

PROFILE = ""  # no ROS profile: plain JSON messages
INSTALL = "pip install 'pyrt[mcap]'"


def require_mcap() -> None:
    """CommandError saying what to install if the mcap library is not there."""
    _writer_class()


def _writer_class() -> Any:
    try:
        from mcap.writer import Writer
    except ImportError:
        raise CommandError(f"MCAP files need the mcap library, which is not installed: "
                           f"{INSTALL}") from None
    return Writer


class JsonMcap:
    """An MCAP file being written into memory: JSON channels with JSON schemas."""

    def __init__(self) -> None:
        writer = _writer_class()
        self.buffer = io.BytesIO()
        self._w = writer(self.buffer)
        self._w.start(profile=PROFILE, library=f"pyrt {__version__}")
        #: Messages written per topic.
        self.counts: dict[str, int] = {}
        self._topic: dict[int, str] = {}
        self._seq: dict[int, int] = {}

    def channel(self, topic: str, title: str, properties: Mapping[str, Mapping[str, Any]],
                description: str = "", schema: Mapping[str, Any] | None = None) -> int:
        """A channel on ``topic`` whose messages are objects with ``properties``
        (each a JSON schema, e.g. ``{"type": "number", "description": "cm"}``);
        or, given, the whole ``schema`` (its title ``title``)."""
        if schema is None:
            schema = {"title": title, "type": "object", "properties": dict(properties),
                      "required": list(properties)}
            if description:
                schema["description"] = description
        sid = self._w.register_schema(name=title, encoding="jsonschema",
                                      data=json.dumps(schema).encode())
        cid = self._w.register_channel(topic=topic, message_encoding="json", schema_id=sid)
        self.counts[topic] = 0
        self._topic[cid] = topic
        self._seq[cid] = 0
        return int(cid)

    def message(self, channel: int, time_ns: int, data: bytes) -> None:
        """One message (JSON text) at ``time_ns``."""
        seq = self._seq[channel]
        self._w.add_message(channel_id=channel, log_time=time_ns, publish_time=time_ns,
                            data=data, sequence=seq)
        self._seq[channel] = seq + 1
        self.counts[self._topic[channel]] += 1

    def metadata(self, name: str, values: Mapping[str, Any]) -> None:
        """A metadata record (every value as text)."""
        self._w.add_metadata(name, {k: v if isinstance(v, str) else json.dumps(v)
                                    for k, v in values.items()})

    def attachment(self, name: str, data: bytes, time_ns: int = 0,
                   media_type: str = "text/plain") -> None:
        """A file carried along (a database)."""
        self._w.add_attachment(create_time=time_ns, log_time=time_ns, name=name,
                               media_type=media_type, data=data)

    def finish(self, path: str | Path) -> int:
        """End the file and write it to ``path`` atomically; its size in bytes."""
        self._w.finish()
        data = self.buffer.getvalue()
        atomic_write(Path(path), data)
        return len(data)


def _template(names: Sequence[str]) -> str:
    """A %-template of a JSON object of integers with these keys."""
    return "{" + ",".join(json.dumps(n).replace("%", "%%") + ":%d" for n in names) + "}"


def _groups(names: Sequence[str]) -> dict[str, list[tuple[int, str]]]:
    """Register names grouped by board (the part before the first '.')."""
    out: dict[str, list[tuple[int, str]]] = {}
    for i, name in enumerate(names):
        board, dot, reg = name.partition(".")
        if not dot:
            board, reg = "board", name
        out.setdefault(board, []).append((i, reg))
    return out


@dataclass(frozen=True)
class Exported:
    """What :func:`export_journal` wrote."""

    path: Path
    size: int
    ticks: int
    journal_size: int
    counts: Mapping[str, int] = field(default_factory=dict)

    def line(self) -> str:
        """One sentence: what went where, and the sizes."""
        n = sum(self.counts.values())
        return (f"{self.ticks} ticks as {n} messages on {len(self.counts)} channels in "
                f"{self.path} ({self.size} bytes; the journal {self.journal_size} bytes)")


@dataclass(frozen=True)
class JointSamples:
    """A station's joints over a run: its declaration, the units of its signals
    (in :meth:`JointStates.signals` order) and their samples (a frame, one row a
    tick, its columns in that order)."""

    joints: JointStates
    units: Sequence[str]
    frame: Frame

    def write(self, m: JsonMcap) -> None:
        """``/joint_states``, a message per sample, and ``/robot_description``."""
        js = self.joints
        if js.urdf:
            c_urdf = m.channel("/robot_description", "std_msgs/msg/String", {},
                               schema=ROBOT_DESCRIPTION_SCHEMA)
            t0 = int(self.frame.t_ns[0]) if len(self.frame.t_ns) else 0
            m.message(c_urdf, t0, _json({"data": js.urdf}))
        cid = m.channel("/joint_states", JOINT_STATE_SCHEMA_NAME, {},
                        schema=JOINT_STATE_SCHEMA)
        factors = [si_factor(u) for u in self.units]
        si = self.frame.data * factors
        for t, row in zip(self.frame.t_ns.tolist(), si.tolist(), strict=True):
            pos, vel, eff = js.split(row)
            m.message(cid, int(t), joint_state_json(int(t), js.names, pos, vel, eff))


def _json(obj: Any) -> bytes:
    return json.dumps(obj, ensure_ascii=False, separators=(",", ":")).encode()


def export_journal(source: str | Path | JournalReader, out: str | Path,
                   joints: JointSamples | None = None) -> Exported:
    """Write the journal ``source`` (a run's or a black box's) to the MCAP file
    ``out`` (see the module text), with ``joints`` on ``/joint_states`` if given;
    JournalError if it cannot be read, CommandError if ``out`` cannot be written
    (nothing written then)."""
    reader = source if isinstance(source, JournalReader) else JournalReader(source)
    h = reader.header
    m = JsonMcap()
    m.metadata("pyrt", {"station": h.station, "period_ns": str(h.period_ns),
                        "version": h.version, "journal": reader.path,
                        **{k: v for k, v in h.metadata.items() if k in ("factory", "args",
                                                                        "boards")}})
    for name, data in h.databases.items():
        m.attachment(name, bytes(data))
    integer = {"type": "integer"}
    ins = [(m.channel(f"/inputs/{board}", f"pyrt.inputs.{board}",
                      {reg: integer for _, reg in regs},
                      f"{h.station}: the input registers of board {board} after the read "
                      "phase"),
            [i for i, _ in regs], _template([reg for _, reg in regs]))
           for board, regs in _groups(h.inputs).items()]
    outs = [(m.channel(f"/outputs/{board}", f"pyrt.outputs.{board}",
                       {reg: integer for _, reg in regs},
                       f"{h.station}: the output registers of board {board} after the "
                       "write phase"),
             [i for i, _ in regs], _template([reg for _, reg in regs]))
            for board, regs in _groups(h.outputs).items()]
    text = {"type": "string"}
    c_tick = m.channel("/ticks", "pyrt.tick", {"tick": integer, "lateness_ns": integer,
                                               "missed": integer})
    c_write = m.channel("/writes", "pyrt.write", {"tick": integer, "register": text,
                                                  "value": integer, "writer": text})
    c_cmd = m.channel("/commands", "pyrt.command", {"tick": integer, "text": text,
                                                    "source": text})
    c_fault = m.channel("/faults", "pyrt.fault", {"tick": integer, "id": integer,
                                                  "message": text})
    c_event = m.channel("/events", "pyrt.event", {"tick": integer, "name": text,
                                                  "id": integer, "message": text})
    maybe = {"type": ["integer", "null"]}  # null: to the end, or not known
    c_gap = m.channel("/gaps", "pyrt.gap", {"first": integer, "last": maybe,
                                            "ticks": maybe, "cause": text})
    writers = reader.writers
    outputs = h.outputs
    ticks = 0
    last_ns = 0
    for rec in reader:
        if isinstance(rec, Gap):
            m.message(c_gap, last_ns, _json({"first": rec.first, "last": rec.last,
                                             "ticks": rec.ticks, "cause": rec.cause}))
            continue
        _tick(m, rec, ins, outs, c_tick, c_write, c_cmd, c_fault, c_event, outputs, writers)
        ticks += 1
        last_ns = rec.time_ns
    if joints is not None:
        joints.write(m)
    try:
        size = m.finish(out)
    except OSError as exc:
        raise CommandError(f"cannot write {out}: {exc.strerror or exc}") from None
    return Exported(Path(out), size, ticks, reader.size, dict(m.counts))


def _tick(m: JsonMcap, t: Tick, ins: Iterable[tuple[int, list[int], str]],
          outs: Iterable[tuple[int, list[int], str]], c_tick: int, c_write: int, c_cmd: int,
          c_fault: int, c_event: int, outputs: Sequence[str], writers: Sequence[str]) -> None:
    now = t.time_ns
    for cid, idx, tpl in ins:
        values = t.inputs
        m.message(cid, now, (tpl % tuple(values[i] for i in idx)).encode())
    for cid, idx, tpl in outs:
        values = t.output_values
        m.message(cid, now, (tpl % tuple(values[i] for i in idx)).encode())
    m.message(c_tick, now, b'{"tick":%d,"lateness_ns":%d,"missed":%d}'
              % (t.tick, t.lateness_ns, t.missed))
    for index, value, writer in t.outputs:
        m.message(c_write, now, _json({
            "tick": t.tick, "register": outputs[index], "value": value,
            "writer": writers[writer] if 0 <= writer < len(writers) else str(writer)}))
    for c in t.commands:
        m.message(c_cmd, now, _json({"tick": t.tick, "text": c.text, "source": c.source}))
    for e in t.events:
        if e.name == "fault":
            m.message(c_fault, now, _json({"tick": t.tick, "id": e.id, "message": e.message}))
        else:
            m.message(c_event, now, _json({"tick": t.tick, "name": e.name, "id": e.id,
                                           "message": e.message}))


def save_frame_mcap(frame: Frame, path: str | Path) -> Path:
    """Write a scope frame as MCAP: a channel per object, a message per sample."""
    m = JsonMcap()
    groups: dict[str, list[tuple[int, str]]] = {}
    for k, name in enumerate(frame.channels):
        obj, dot, sig = name.partition(".")
        if not dot or not sig:
            obj, sig = "", name
        groups.setdefault(obj, []).append((k, sig))
    chans = []
    for obj, fields in groups.items():
        props = {sig: {"type": "number", **({"description": frame.unit(k)}
                                            if frame.unit(k) else {})}
                 for k, sig in fields}
        topic = f"/scope/{obj}" if obj else "/scope"
        cid = m.channel(topic, f"pyrt.scope.{obj}" if obj else "pyrt.scope", props,
                        "scope samples" + (f" of {obj}" if obj else ""))
        keys = [json.dumps(sig) for _k, sig in fields]
        chans.append((cid, [k for k, _ in fields], keys))
    m.metadata("pyrt.scope", {"mode": frame.mode, "channels": list(frame.channels),
                              "units": [frame.unit(k) for k in range(len(frame.channels))],
                              "trigger_index": -1 if frame.trigger_index is None
                              else frame.trigger_index, "version": __version__})
    data = frame.data
    for row, t in enumerate(frame.t_ns.tolist()):
        values = data[row]
        for cid, cols, keys in chans:
            body = ",".join(f"{key}:{_number(values[c])}"
                            for key, c in zip(keys, cols, strict=True))
            m.message(cid, int(t), ("{" + body + "}").encode())
    path = Path(path)
    try:
        m.finish(path)
    except OSError as exc:
        raise CommandError(f"scope save: cannot write {path}: {exc.strerror or exc}") from None
    return path


def _number(v: Any) -> str:
    """A float as JSON (NaN and infinities, which JSON lacks, as null)."""
    f = float(v)
    if f != f or f in (float("inf"), float("-inf")):
        return "null"
    return repr(f) if not f.is_integer() else str(int(f)) if abs(f) < 2**53 else repr(f)
