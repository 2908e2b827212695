"""The scope's samples, live, on a Foxglove WebSocket server (``pyrt[foxglove]``).

``scope foxglove [PORT]`` serves, on ``ws://127.0.0.1:PORT`` (loopback, as
every pyrt server is; default :data:`DEFAULT_PORT`, Foxglove's own), at most
``HZ`` samples a second of loop time (default :data:`DEFAULT_HZ`):

* ``/scope/OBJECT`` (``/scope`` for a signal named alone): one JSON message
  per sample with the object's channels (``{"x": 21.07, "y": 0.0}``), the
  same channels and schemas as ``scope save FILE.mcap`` writes;
* for a robot whose root declares its joints (:class:`~pyrt.scope.joints.JointStates`):
  ``/joint_states`` (``sensor_msgs/msg/JointState``, SI units) and
  ``/robot_description`` (its URDF as ``std_msgs/msg/String``, sent again
  every :data:`DESCRIPTION_EVERY_S` s so that a panel opened later has it):
  Foxglove's 3D panel (a URDF layer on topic ``/robot_description``) shows the
  robot moving.

Messages carry the loop's time (ns) as log time.  The loop never waits for a
client: in the loop thread the scope only appends the sample's packed bytes
to a bounded queue (:meth:`FoxgloveServer.offer`; a full queue drops the
sample and counts it); a thread of the server turns them into JSON and logs
them; the SDK's server keeps a bounded backlog per client and drops the
oldest for a slow one.
"""

from __future__ import annotations

import collections
import json
import threading
import time
import weakref
from collections.abc import Sequence
from typing import Any

from pyrt.errors import CommandError
from pyrt.scope.joints import (
    JOINT_STATE_SCHEMA,
    JOINT_STATE_SCHEMA_NAME,
    ROBOT_DESCRIPTION_SCHEMA,
    JointStates,
    joint_state_json,
    si_factor,
)
from pyrt.scope.stream import MAX_HZ, MIN_HZ, Layout

__all__ = ["DEFAULT_HZ", "DEFAULT_PORT", "INSTALL", "FoxgloveServer"]

#: Foxglove's default port.
DEFAULT_PORT = 8765
#: Samples a second of loop time, unless the command names a rate.
DEFAULT_HZ = 50.0
#: How often the robot description is sent again (wall time, s).
DESCRIPTION_EVERY_S = 1.0
#: Samples the queue toward the server's thread holds.
QUEUE = 4096
#: How often the thread looks at its queue, s (wall time).
POLL_S = 0.01
#: Messages the SDK keeps per client before it drops the oldest.
BACKLOG = 1024
INSTALL = "pip install 'pyrt[foxglove]'"


def _sdk() -> Any:
    try:
        import foxglove
    except ImportError:
        raise CommandError("scope foxglove needs the Foxglove SDK, which is not installed: "
                           f"{INSTALL}") from None
    return foxglove


class FoxgloveServer:
    """A Foxglove live server of scope samples (see the module text);
    :meth:`offer` is the loop's side.  ``joints``: the robot's declaration and
    the units of each of its signals (in :meth:`JointStates.signals` order),
    or None."""

    def __init__(self, port: int = DEFAULT_PORT, hz: float = DEFAULT_HZ,
                 host: str = "127.0.0.1", units: dict[str, str] | None = None,
                 joints: tuple[JointStates, Sequence[str]] | None = None):
        if not isinstance(hz, int | float) or isinstance(hz, bool) \
                or not MIN_HZ <= hz <= MAX_HZ:
            raise CommandError(f"scope foxglove: rate must be {MIN_HZ:g}..{MAX_HZ:g} Hz, "
                               f"got {hz!r}")
        if not isinstance(port, int) or not 0 <= port <= 65535:
            raise CommandError(f"scope foxglove: port {port!r} outside 0..65535")
        fox = _sdk()
        self._fox = fox
        self.hz = float(hz)
        self.period_ns = round(1e9 / hz)
        #: The units of the scope's channels (for the schemas' descriptions).
        self.units = dict(units or {})
        self._joints = joints[0] if joints else None
        self._factors = [si_factor(u) for u in joints[1]] if joints else []
        self._ctx = fox.Context()
        try:
            self._server = fox.start_server(name="pyrt", host=host, port=port,
                                            context=self._ctx, message_backlog_size=BACKLOG)
        except Exception as exc:  # the SDK raises its own error for a taken port
            raise CommandError(f"scope foxglove: cannot serve on {host}:{port}: {exc}") from None
        self.host, self.port = host, int(self._server.port)
        self._queue: collections.deque[tuple[Layout, bytes]] = collections.deque()
        #: Samples sent; samples the queue had no room for (the thread fell behind).
        self.sent = 0
        self.dropped = 0
        self._channels: dict[str, Any] = {}
        self._plans: dict[Layout, Any] = {}
        self._description = None
        self._joint_channel = None
        if self._joints is not None:
            self._joint_channel = fox.Channel("/joint_states", schema=fox.Schema(
                name=JOINT_STATE_SCHEMA_NAME, encoding="jsonschema",
                data=json.dumps(JOINT_STATE_SCHEMA).encode()), message_encoding="json",
                context=self._ctx)
            if self._joints.urdf:
                self._description = fox.Channel("/robot_description", schema=fox.Schema(
                    name="std_msgs/msg/String", encoding="jsonschema",
                    data=json.dumps(ROBOT_DESCRIPTION_SCHEMA).encode()),
                    message_encoding="json", context=self._ctx)
        self._stop = threading.Event()
        self._owner: weakref.ref[object] | None = None
        self._thread = threading.Thread(target=self._run, name="pyrt foxglove", daemon=True)
        self._thread.start()

    @property
    def url(self) -> str:
        """Where Foxglove connects."""
        return f"ws://{self.host}:{self.port}"

    # -- the loop's side -----------------------------------------------------------

    def offer(self, layout: Layout, row: bytes) -> None:
        """Hand one packed sample over (loop thread): an append, or a count when
        the queue is full."""
        if len(self._queue) >= QUEUE:
            self.dropped += 1
            return
        self._queue.append((layout, row))

    def bind(self, owner: object) -> None:
        """Tie the server's thread to ``owner`` (the scope): once it is gone, the
        thread stops the server and ends."""
        self._owner = weakref.ref(owner)

    # -- the server's thread ---------------------------------------------------------

    def _run(self) -> None:
        next_description = 0.0
        while not self._stop.wait(POLL_S):
            if self._description is not None and time.monotonic() >= next_description:
                assert self._joints is not None
                self._description.log(json.dumps({"data": self._joints.urdf}).encode())
                next_description = time.monotonic() + DESCRIPTION_EVERY_S
            self.drain()
            owner = self._owner
            if owner is not None and owner() is None:
                self._server.stop()
                break

    def _plan(self, layout: Layout) -> Any:
        """How a sample of ``layout`` becomes messages: per object, its channel and
        columns; and where the joint signals are among the columns (or None)."""
        groups: dict[str, list[tuple[int, str]]] = {}
        for k, name in enumerate(layout.channels):
            obj, dot, sig = name.partition(".")
            if not dot or not sig:
                obj, sig = "", name
            groups.setdefault(obj, []).append((k, sig))
        chans = []
        for obj, fields in groups.items():
            topic = f"/scope/{obj}" if obj else "/scope"
            key = topic + "\0" + ",".join(sig for _k, sig in fields)
            ch = self._channels.get(key)
            if ch is None:
                props = {sig: {"type": ["number", "null"],
                               **({"description": self.units[layout.channels[k]]}
                                  if self.units.get(layout.channels[k]) else {})}
                         for k, sig in fields}
                schema = {"title": f"pyrt.scope.{obj}" if obj else "pyrt.scope",
                          "type": "object", "properties": props}
                old = next((c for kk, c in self._channels.items()
                            if kk.startswith(topic + "\0")), None)
                if old is not None:  # the object's channels changed: a new schema
                    old.close()
                    self._channels = {kk: c for kk, c in self._channels.items() if c is not old}
                ch = self._channels[key] = self._fox.Channel(
                    topic, schema=self._fox.Schema(name=schema["title"], encoding="jsonschema",
                                                   data=json.dumps(schema).encode()),
                    message_encoding="json", context=self._ctx)
            chans.append((ch, [(k, json.dumps(sig)) for k, sig in fields]))
        where = None
        if self._joints is not None:
            index = {name: k for k, name in enumerate(layout.channels)}
            wanted = self._joints.signals()
            if all(n in index for n in wanted):
                where = [index[n] for n in wanted]
        plan = self._plans[layout] = (chans, where)
        return plan

    def drain(self) -> int:
        """Log what is queued (the server's thread); the number of samples."""
        queue = self._queue
        n = 0
        while queue:
            layout, row = queue.popleft()
            plan = self._plans.get(layout) or self._plan(layout)
            chans, where = plan
            values = layout.packer.unpack(row)
            t_ns = values[0]
            for ch, cols in chans:
                body = ",".join(f"{key}:{_number(values[1 + k])}" for k, key in cols)
                ch.log(("{" + body + "}").encode(), log_time=t_ns)
            if where is not None and self._joint_channel is not None and self._joints:
                si = [values[1 + k] * f for k, f in zip(where, self._factors, strict=True)]
                pos, vel, eff = self._joints.split(si)
                self._joint_channel.log(joint_state_json(t_ns, self._joints.names, pos, vel,
                                                         eff), log_time=t_ns)
            n += 1
        self.sent += n
        return n

    def close(self) -> None:
        """Log what is queued, stop the thread and the server."""
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=5)
        self.drain()
        self._server.stop()

    def describe(self) -> str:
        """One line: where, how often, and what was sent and dropped."""
        line = f"Foxglove server on {self.url} at {self.hz:g} Hz of loop time: {self.sent} sent"
        if self._joints is not None:
            line += (", with /joint_states" + (" and /robot_description"
                                               if self._description is not None else ""))
        if self.dropped:
            line += f", {self.dropped} dropped (the server fell behind the loop)"
        return line


def _number(v: float) -> str:
    f = float(v)
    if f != f or f in (float("inf"), float("-inf")):
        return "null"
    return str(int(f)) if f.is_integer() and abs(f) < 2**53 else repr(f)
