"""SENSORS (002, routine at 0473): read the sensor ports, show them on the LEDs.

The 8155's port A (proximity sensors) goes to RAM 2D, port B (the other
sensors: limit, ...) to 2E; both are written to the LED latches.
"""

from __future__ import annotations

from pyrt.boards.gripper import LED_HI, LED_LO, P8155_PA, P8155_PB
from pyrt.boards.i8031 import OTHER, PROX
from pyrt.tasks._i8031 import Controller8031

__all__ = ["ADDRESS", "NAME", "sensors"]

#: Appendix B: the routine's EPROM address, and its name on the ready queue.
ADDRESS = 0x0473
NAME = "SENSORS"


def sensors(ctl: Controller8031) -> None:
    """SENSORS (0473): read the 8155 ports into 2D/2E, show them on the LEDs."""
    ram = ctl.ram
    cpu = ctl.cpu
    ram[PROX] = cpu.movx_read(P8155_PA)
    ram[OTHER] = cpu.movx_read(P8155_PB)
    cpu.movx_write(LED_LO, ram[PROX])
    cpu.movx_write(LED_HI, ram[OTHER])
