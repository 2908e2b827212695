"""The rope manipulator as the server serves it: status fields, shell, command classes.

STATUS fields: the source position ``x y z`` (cm), ``distErr`` (cm),
``netForce`` (N, residual), ``moving`` (a move runs or waits), ``fault``,
then ``tension0`` ... one per rope, in the station's axis order (N).

Read-only without privilege: the words ``help``, ``stats``, ``status``,
``sim`` with no argument; the PolyAxis's ``tensions`` and ``netForce``
(computed from what is measured), an Encoder's ``read`` and the AV's
``show``.  Everything else (``to``, ``pattern``, ``stop``, axis moves,
calibration, ``ack``, ``log``, ``debug``, ``wait``, ``sleep``, faults in the
simulation) needs ``AUTH``.  An Encoder's ``read`` prints through the
device to the console's message stream, not into the reply.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, TextIO

from pyrt.commands.manipulator import ManipulatorShell
from pyrt.robots.axis import Axis
from pyrt.scope import Source

__all__ = ["ManipulatorService"]

_READ_WORDS = frozenset({"help", "stats", "status"})
_READ_OBJECT = {"polyaxis": {"tensions", "netforce"}, "encoder": {"read"}, "av": {"show"}}


class ManipulatorService:
    """:class:`~pyrt.server.robot.ServedRobot` of a
    :class:`~pyrt.station.manipulator.ManipulatorStation`."""

    def __init__(self, station: Any):
        self.station = station
        self.pa = station.polyaxis
        self.name = self.pa.name
        self.status_names = (
            "x", "y", "z", "distErr", "netForce", "moving", "fault",
            *(f"tension{i}" for i in range(len(station.axes))),
        )

    def status_sources(self) -> list[Source]:
        st, pa = self.station, self.pa
        return [
            Source.call(lambda: pa.position[0]),
            Source.call(lambda: pa.position[1]),
            Source.call(lambda: pa.position[2]),
            Source.call(lambda: pa.dist_err),
            Source.call(lambda: pa.net_force_magnitude),
            Source.call(st.busy),
            Source.call(lambda: st.queue.fault is not None),
            *(Source.call(lambda i=i: pa.tensions[i]) for i in range(len(st.axes))),
        ]

    def format_status(self, values: Sequence[Any]) -> str:
        x, y, z, dist, net, moving, fault, *tensions = values
        head = (f"x={x:.2f} y={y:.2f} z={z:.2f} distErr={dist:.3f} netForce={net:.2f} "
                f"moving={int(bool(moving))} fault={int(bool(fault))}")
        return head + "".join(f" tension{i}={t:.2f}" for i, t in enumerate(tensions))

    def make_shell(self, runner: Any, stdout: TextIO) -> ManipulatorShell:
        return ManipulatorShell(runner, self.station, stdout)

    def _kind(self, obj: Any) -> str:
        st = self.station
        if obj is self.pa:
            return "polyaxis"
        if isinstance(obj, Axis):
            return "axis"
        if any(obj is a.encoder for a in st.axes):
            return "encoder"
        if any(obj is a.motor or obj is a.loadcell for a in st.axes):
            return "device"
        return "av"

    def is_read_only(self, line: str) -> bool:
        words = line.split()
        if not words:
            return True
        word = words[0].lower()
        if hasattr(ManipulatorShell, "do_" + word):
            if word == "sim":
                return len(words) == 1
            return word in _READ_WORDS
        obj = self.station.objects.get(word)
        if obj is None:
            return False
        if len(words) < 2:
            return True  # the shell answers with the object's command list
        return words[1].lower() in _READ_OBJECT.get(self._kind(obj), ())

    def stop_all(self) -> None:
        self.station.stop_all()

    def release(self, shell: Any) -> None:
        """Nothing belongs to a manipulator session alone."""
