"""What the gripper routines need of the controller they run on (duck-typed)."""

from __future__ import annotations

from typing import Any, Protocol

__all__ = ["Controller8031"]


class Controller8031(Protocol):
    """The 002 controller as its self-scheduling routines see it.

    ``ram`` is the 8031's on-chip RAM image (Appendix A): the routines share
    state only through it.  ``cpu`` reads and writes the external data space
    (``movx_read(addr)``, ``movx_write(addr, byte)``); ``drive(byte)``
    writes the DAC and remembers it; ``job`` is the foreground job (init,
    calibration) or None; ``last_stop`` says why the last move or jog ended;
    ``move_ended(why)`` is told when MVJAWS ends a commanded move.
    """

    ram: bytearray
    cpu: Any
    job: Any
    last_stop: str
    #: The commanded move's supervision (:class:`pyrt.tasks.jawmove.MoveSupervisor`).
    supervisor: Any

    def drive(self, byte: int) -> None: ...

    def move_ended(self, why: str) -> None: ...
