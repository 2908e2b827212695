"""The reflex over a dead link: the write fails (recorded), the controller's own state is cleared."""

from __future__ import annotations

import pytest

from pyrt.boards import open_boards
from pyrt.boards.gripper import DAC_NULL
from pyrt.boards.i8031 import FLAGS, I8031
from pyrt.boards.modbus import builtin_map
from pyrt.boards.modbusmap import load_map
from pyrt.boards.tio10 import TIO10
from pyrt.devices.motor import OFF, ON, Motor
from pyrt.errors import BoardError
from pyrt.robots.gripper import _MASK_DOJOG, _MASK_DRVON, GripperController
from pyrt.sim.modbusserver import ModbusBoardServer
from pyrt.sim.world import GRIPPER_BOARDS, GripperWorld


def test_gripper_reflex_over_a_dead_modbus_link_raises_and_still_clears_its_state():
    """Drive on, a job running, the Modbus server gone: reflex raises BoardError naming the
    URL, and the controller's DAC copy is null, its drive and jog flags clear, its job gone."""
    world = GripperWorld(start=-0x100)
    server = ModbusBoardServer(world, load_map(builtin_map("gripper"), GRIPPER_BOARDS),
                               watchdog_s=30.0)
    server.start()
    cpu = I8031()
    boards = open_boards(f"{server.url}?map=builtin:gripper", "gripper", GRIPPER_BOARDS,
                         cpu=cpu)
    try:
        ctl = GripperController(cpu)
        ctl.drive(0x90)
        ctl.ram[FLAGS] |= _MASK_DRVON | _MASK_DOJOG
        job = ctl.job = type("Job", (), {"cancelled": False,
                                         "cancel": lambda self: setattr(self, "cancelled",
                                                                        True)})()
        assert world.registers("gripper").read("dac") == 0x90
        server.close()
        with pytest.raises(BoardError) as err:
            boards.poll(0)  # the link is found dead
        assert err.value.url == boards.url
        with pytest.raises(BoardError, match="link is down"):
            ctl.reflex()
        assert ctl.dac == DAC_NULL
        assert not ctl.ram[FLAGS] & (_MASK_DRVON | _MASK_DOJOG)
        assert ctl.job is None and job.cancelled
        assert not ctl.supervisor.active
    finally:
        boards.close()


class _DeadTIO10(TIO10):
    """A TIO10 whose link died: every write raises BoardError."""

    dead = False

    def disarm(self, channel: int) -> None:
        if self.dead:
            raise BoardError("modbus://127.0.0.1:1", "write: the link is down")
        super().disarm(channel)


def test_motor_stop_over_a_dead_link_raises_and_still_clears_its_state():
    """Motor.stop whose disarm fails: BoardError, and the motor is OFF, at zero velocity, its
    move ended where it was."""
    tio = _DeadTIO10()
    m = Motor("axis0Motor", tio, 7, 0.5, 7.0)
    m.velocity_mode()
    m.state, m.velocity, m.desired_velocity = ON, 3.0, 3.0
    tio.dead = True
    with pytest.raises(BoardError):
        m.stop()
    assert m.state == OFF and m.velocity == 0.0 and m.desired_velocity == 0.0
    assert m.desired_steps == m.steps_taken
