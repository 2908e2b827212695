"""Gripper faults: no current is ever left on a motor that does not move."""

from __future__ import annotations

import pytest
from _gripper_rig import MS, make_rig, signed

from pyrt.boards.gripper import P8155_PA
from pyrt.errors import CommandError

#: 002's central fix, with pyrt's stall watchdog behind it.
STALL_BOUND_NS = 1000 * MS + 2 * MS


def test_dead_limit_sensor_aborts_init_with_current_nulled():
    """A dead limit sensor: I stops at the open stop, nulls the current, reports failure."""
    rig = make_rig(start=-0x0C00)
    rig.plant.inject("limit")
    job = rig.ctl.start_init()
    result = rig.run_job(job, max_s=10)
    assert not result.ok and "limit" in result.message
    assert rig.board.dac == 0x80
    assert rig.loop.now_ns < 3000 * MS  # bounded: travel time plus a few queue checks
    assert rig.stall.worst_ns < 200 * MS
    assert rig.loop.take_fault() is None  # the sequence itself caught it


def test_jammed_motor_during_p_ends_with_drive_clear_and_current_null():
    """A jammed motor during P: the stopped bit and STOPCNT end the move, drive bit clear."""
    rig = make_rig()
    rig.init()
    rig.plant.inject("jam")
    rig.ctl.move(-0x1000)
    assert rig.loop.run_until(lambda: not rig.ctl.moving, 2000)
    assert not rig.cpu.ram[0x2C] & 0x08
    assert rig.board.dac == 0x80
    assert rig.stall.worst_ns < 300 * MS


def test_jammed_motor_aborts_init():
    """A jammed motor at power-up: init aborts, current null, well before the watchdog."""
    rig = make_rig()
    rig.plant.inject("jam")
    result = rig.run_job(rig.ctl.start_init(), max_s=5)
    assert not result.ok and rig.board.dac == 0x80
    assert rig.stall.worst_ns < 200 * MS


def test_dead_encoder_aborts_init():
    """A dead encoder looks like stopped jaws: init aborts with the current nulled."""
    rig = make_rig()
    rig.plant.inject("encoder")
    result = rig.run_job(rig.ctl.start_init(), max_s=5)
    assert not result.ok and rig.board.dac == 0x80


def test_stuck_limit_port_makes_init_think_it_is_open():
    """Port 2E stuck at 00 (all its sensors on): init believes the limit at once, moves nothing."""
    rig = make_rig(start=-0x0800)
    rig.plant.inject("port", 0x00, port="2E")
    result = rig.run_job(rig.ctl.start_init(), max_s=5)
    assert result.ok  # 002's program cannot tell: the limit bit says wide open
    assert rig.plant.x == pytest.approx(-0x0800, abs=2)
    assert rig.ctl.sensor_word() >> 8 == 0xF8  # bits 3-7 of port B float high


def test_routine_raising_runs_the_reflex_in_the_same_tick():
    """An exception in a routine faults the robot: DAC null and drive bit clear in that tick."""
    rig = make_rig()
    rig.init()
    rig.ctl.move(-0x1000)
    rig.loop.run(200)
    assert rig.board.dac != 0x80

    def unplugged():  # the 8155 port that SENSORS reads fails
        raise RuntimeError("sensor board unplugged")

    rig.cpu.map_xdata(P8155_PA, read=unplugged)
    tick = None
    for _ in range(200):
        rig.loop.run(1)
        if rig.station.fault is not None:
            tick = rig.loop.tick_index
            break
    assert tick is not None
    assert rig.board.dac == 0x80 and not rig.ctl.moving
    fault = rig.loop.take_fault()
    assert fault.source == "SENSORS" and fault.tick == tick - 1


def test_corrupted_q_slot_faults_and_nulls():
    """Monitor C writing a bogus address into Q: the queue faults, the reflex nulls the DAC."""
    rig = make_rig()
    rig.init()
    rig.ctl.move(-0x1000)
    rig.loop.run(100)
    rig.ctl.poke(0x35, 0x12)  # Q slot 0 now holds an address with no routine
    rig.ctl.poke(0x36, 0x34)
    rig.loop.run(100)
    assert rig.station.fault is not None
    assert rig.board.dac == 0x80 and not rig.ctl.moving


def test_full_queue_during_a_sequence_is_a_fault():
    """A ready queue filled through the monitor: the sequence's WAIT faults the robot, DAC null."""
    rig = make_rig()
    rig.init()
    for slot in range(3, 6):  # fill the three free slots with WATCHJAW, far in the future
        rig.ctl.poke(0x2F + slot, 0xFF)
        rig.ctl.poke(0x35 + 2 * slot, 0x41)
        rig.ctl.poke(0x36 + 2 * slot, 0x05)
    job = rig.ctl.start_init()
    rig.loop.run(5)
    assert job.done and not job.value().ok
    assert rig.station.fault is not None and rig.board.dac == 0x80


def test_clock_off_mid_move_ends_the_move_with_current_nulled():
    """Clock interrupt off during a move (monitor I): the move ends in that call, current nulled."""
    rig = make_rig()
    rig.init()
    rig.ctl.move(-0x0400)
    rig.loop.run(300)
    assert rig.board.dac != 0x80
    rig.ctl.toggle_clock()  # MVJAWS frozen: it could not end the move any more
    assert rig.board.dac == 0x80 and not rig.ctl.moving
    rig.stall.worst_ns = 0
    assert "clock interrupt turned off" in rig.ctl.last_stop
    rig.loop.run(3000)
    assert rig.board.dac == 0x80 and rig.stall.worst_ns == 0
    assert rig.loop.take_fault() is None


def test_watchdog_trips_when_the_queue_is_frozen_under_a_latched_current():
    """The queue frozen behind the controller's back with current latched: a bound trips, current nulled."""
    rig = make_rig()
    rig.init()
    rig.ctl.move(-0x0400)
    rig.loop.run(300)
    rig.ctl.queue.interrupts_enabled = False  # not through the monitor: nothing ends the move
    rig.loop.run(15000)
    assert rig.board.dac == 0x80
    assert rig.stall.worst_ns <= rig.ctl.stall_bound_ns() + 2 * MS
    fault = rig.loop.take_fault()
    # the move's settle bound (checked every tick) or the stall bound, whichever first
    assert fault is not None and fault.source in ("P move", "stall watchdog")


def test_watchdog_trips_when_mvjaws_is_removed_from_q():
    """MVJAWS taken off the queue mid-move: the watchdog still bounds the stall."""
    rig = make_rig()
    rig.init()
    rig.ctl.move(-0x1000)
    rig.loop.run(300)
    for slot in range(6):
        if rig.ctl.word(0x35 + 2 * slot) == 0x04C2:
            rig.ctl.poke(0x35 + 2 * slot, 0)
            rig.ctl.poke(0x36 + 2 * slot, 0)
    rig.loop.run(15000)
    assert rig.board.dac == 0x80 and rig.stall.worst_ns <= STALL_BOUND_NS


def test_acknowledge_restarts_the_routines_without_moving():
    """After a fault, acknowledge restarts the three routines; nothing moves until P."""
    rig = make_rig()
    rig.init()
    rig.station.trip("test fault", source="test")
    assert rig.board.dac == 0x80
    p = rig.ctl.find_command("P")
    with pytest.raises(CommandError, match="give 'ack' first"):
        rig.station.execute(rig.ctl, p, p.parse(["-100"]))
    rig.station.acknowledge()
    assert sorted(rig.ctl.queue.pending()) == ["MVJAWS", "SENSORS", "WATCHJAW"]
    rig.loop.run(500)
    assert rig.board.dac == 0x80
    assert abs(rig.move(-0x100) + 0x100) <= 16
    assert signed(rig.ctl.target()) == -0x100
