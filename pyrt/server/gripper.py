"""The gripper as the server serves it: status fields, shell, command classes.

Read-only without privilege (nothing else changes the jaws, the RAM, the
loop's time or a file): at ``CMD:`` the letters ``E S T W``; the words
``help``, ``stats``, ``sim`` with no argument (the simulated world's state)
and the scope's read-outs (``scope``, ``scope list|status|show``).
Everything else (``P``, ``X``, ``I``, ``C``, the monitor ``M``, ``wait``,
``sleep``, ``sim`` settings, scope changes and files) needs ``AUTH``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, TextIO

from pyrt.boards.i8031 import COMMAND_CNT, ENCODER_CNT, PROX
from pyrt.commands.gripper import GripperShell
from pyrt.errors import Fault
from pyrt.scope import Source

__all__ = ["GripperService"]

_READ_LETTERS = frozenset("ESTW")
_READ_WORDS = frozenset({"help", "stats"})  # and ack, wait ... need AUTH
_READ_SCOPE = frozenset({"list", "status", "show"})


class GripperService:
    """:class:`~pyrt.server.robot.ServedRobot` of a
    :class:`~pyrt.robots.gripper.GripperController` (``plant``: the
    simulated jaws for the ``sim`` word, None on hardware; ``scope`` and
    ``executor``: the station's, as the console gets them).
    :meth:`from_station` takes them from a
    :class:`~pyrt.station.gripper.GripperStation`."""

    status_names = ("position", "target", "moving", "busy", "sensors", "fault")

    def __init__(
        self,
        controller: Any,
        plant: Any = None,
        name: str = "gripper",
        *,
        scope: Any = None,
        executor: Any = None,
    ):
        self.ctl = controller
        self.plant = plant
        self.name = name
        self.scope = scope
        self.executor = executor

    @classmethod
    def from_station(cls, station: Any) -> GripperService:
        """The service of a built gripper station."""
        return cls(station.controller, station.plant, scope=station.scope,
                   executor=station.executor)

    def status_sources(self) -> list[Source]:
        ctl = self.ctl
        ram = ctl.ram
        return [
            Source.word(ram, ENCODER_CNT, signed=True),
            Source.word(ram, COMMAND_CNT, signed=True),
            Source.call(lambda: ctl.moving),
            Source.call(lambda: ctl.busy),
            Source.word(ram, PROX),
            Source.call(lambda: ctl.queue.fault is not None),
        ]

    def format_status(self, values: Sequence[Any]) -> str:
        pos, tgt, moving, busy, sensors, fault = values
        return (
            f"position={int(pos)} target={int(tgt)} moving={int(bool(moving))} "
            f"busy={int(bool(busy))} sensors=0x{int(sensors):04X} fault={int(bool(fault))}"
        )

    def make_shell(self, runner: Any, stdout: TextIO) -> GripperShell:
        return GripperShell(runner, self.ctl, stdout, plant=self.plant, scope=self.scope,
                            executor=self.executor)

    def is_read_only(self, line: str) -> bool:
        text = line.strip()
        if not text:
            return True
        word, _, rest = text.partition(" ")
        lower = word.lower()
        if len(word) > 1 and hasattr(GripperShell, "do_" + lower):
            if lower in _READ_WORDS:
                return True
            args = rest.split()
            if lower == "sim":
                return not args
            if lower == "scope":
                return not args or args[0].lower() in _READ_SCOPE
            return False
        # A letter command (the shell reads the first character as the letter).
        return text[0].upper() in _READ_LETTERS

    def stop_all(self) -> None:
        # The reflex action is exactly "every motor stopped": null the
        # current, clear drive and jog, abandon a running init.
        # (the station's reflex also ends the motion and drops queued moves).
        self.ctl.queue.reflex(
            Fault(robot=self.name, cause="every motor stopped", source="server"))

    def release(self, shell: Any) -> None:
        if getattr(shell, "in_monitor", False):
            shell.onecmd("Q")
