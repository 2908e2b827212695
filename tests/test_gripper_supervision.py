"""Supervised jaw moves: every schedule 002 lets the operator set ends in a settled move,
a truthful "stopped short", or a supervision fault within the bound, with the current nulled."""

from __future__ import annotations

import pytest
from _gripper_rig import MS, make_rig, signed
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pyrt.boards import open_boards
from pyrt.boards.i8031 import DRVON, FLAGS, MVJAWSPD, SENSORPD, SYSCLKPD, WTCHJWSPD
from pyrt.errors import CommandError
from pyrt.robots.gripper import Schedule
from pyrt.scheduler import Loop, SimClock
from pyrt.sim.gripper import JawPlant
from pyrt.sim.world import GRIPPER_BOARDS
from pyrt.station.gripper import AT_TARGET_COUNTS, GripperStation
from pyrt.tasks import jawmove

TARGET = -0x1B86


def station_rig(tick_us: int = 1000):
    """A gripper station on a SimClock with ``tick_us``, initialised."""
    boards = open_boards("sim:", "gripper", GRIPPER_BOARDS)
    plant = JawPlant(boards.simulated["gripper"])  # the world's side
    loop = Loop(SimClock(), period_ns=tick_us * 1000)
    station = GripperStation(loop, boards, plant)
    ctl = station.controller
    job = ctl.start_init()
    assert loop.run_until(lambda: job.done, 120_000_000 // tick_us), "init hung"
    result = job.value()
    return station, ctl, plant, loop, result


def supervised_move(station, ctl, loop, target: int) -> tuple[int, int]:
    """P ``target``; run until the move ends or faults.  Returns (ns taken, settle bound ns)."""
    ctl.move(target)
    bound = int(ctl.settle_bound_s * 1e9)
    t0 = loop.now_ns
    limit = (bound + 2 * ctl.stall_limit_ns) // loop.period_ns + 10
    ended = loop.run_until(lambda: not ctl.moving or station.fault is not None, limit)
    assert ended, f"still driving {limit} ticks after P"
    return loop.now_ns - t0, bound


REPRODUCTIONS = [
    pytest.param({SYSCLKPD: 0x0C}, id="SYSCLKPD 0C"),
    pytest.param({MVJAWSPD: 0x30}, id="MVJAWSPD 30"),
    pytest.param({WTCHJWSPD: 0x18}, id="WTCHJWSPD 18"),
]


@pytest.mark.parametrize("pokes", REPRODUCTIONS)
def test_reproductions_settle_or_trip_within_the_bound(pokes):
    """M, C 4x yy, Q, I, P-1B86: a settled move or the supervision's fault within the bound, current zero."""
    rig = make_rig()
    rig.init()
    for addr, value in pokes.items():
        rig.ctl.poke(addr, value)
    rig.init()  # the sequence: I after the change
    taken, bound = supervised_move(rig.station, rig.ctl, rig.loop, TARGET)
    assert taken <= bound + MS
    assert rig.board.dac == 0x80 and not rig.cpu.ram[FLAGS] & (1 << DRVON)
    fault = rig.station.fault
    if fault is None:
        assert abs(signed(rig.ctl.position()) - TARGET) <= AT_TARGET_COUNTS
    else:
        assert fault.source == "P move" and "P move" in fault.cause
    rig.loop.run(2000)  # and it stays that way: nothing hunts on
    assert rig.board.dac == 0x80


def test_large_wtchjwspd_oscillation_is_caught_as_such():
    """WTCHJWSPD 18: MVJAWS drives with WATCHJAW's stale error; the oscillation trips a fault naming it."""
    rig = make_rig()
    rig.init()
    rig.ctl.poke(WTCHJWSPD, 0x18)
    taken, bound = supervised_move(rig.station, rig.ctl, rig.loop, TARGET)
    fault = rig.station.fault
    assert fault is not None, "the stale error did not make the jaws oscillate"
    assert fault.cause.startswith("P move oscillating about the target: error ±")
    assert "sign changes without decay" in fault.cause
    assert "WTCHJWSPD 18 ≫ MVJAWSPD 0C" in fault.cause
    assert taken < bound  # caught by the sign changes, before the settle bound
    assert rig.board.dac == 0x80 and rig.plant.current == 0


def test_a_stale_stopped_bit_ends_the_move_short_and_wait_says_why():
    """WTCHJWSPD 40 ≫ MVJAWSPD 02: the stopped bit lies (002) and ends the move; wait says so."""
    rig = make_rig()
    rig.init()
    rig.ctl.poke(WTCHJWSPD, 0x40)
    rig.ctl.poke(MVJAWSPD, 0x02)
    taken, bound = supervised_move(rig.station, rig.ctl, rig.loop, TARGET)
    assert rig.station.fault is None and taken < bound and rig.board.dac == 0x80
    assert rig.station.last_move is not None
    report = rig.station.last_move.report[0]
    short = signed(rig.ctl.position()) - TARGET
    assert report.startswith(f"stopped short of the target by {short} counts (the stopped bit "
                             "ended the move (STOPCNT ran out); WTCHJWSPD 40 ≫ MVJAWSPD 02")


def test_a_move_that_does_not_settle_names_the_bound_and_the_schedule():
    """MVJAWSPD 30: the move outlives its settle bound; the fault says so, with the error and the cause."""
    rig = make_rig()
    rig.init()
    rig.ctl.poke(MVJAWSPD, 0x30)
    supervised_move(rig.station, rig.ctl, rig.loop, TARGET)
    fault = rig.station.fault
    assert fault is not None
    assert fault.cause.startswith(f"P move did not settle within {rig.ctl.settle_bound_s:.1f} s: "
                                  "error ")
    assert "MVJAWSPD 30" in fault.cause
    assert rig.board.dac == 0x80


def test_mvjaws_uses_the_error_watchjaw_left_in_ram():
    """With the queue frozen MVJAWS's drive follows ERROR_CNT as written, not the encoder."""
    rig = make_rig()
    rig.init()
    ctl = rig.ctl
    ctl.move(-0x100)
    ctl._set_word(0x46, 0x80 + 5)  # WATCHJAW says: 5 counts past the target
    jawmove.mvjaws(ctl)
    assert rig.board.dac == 0x80 - 5  # drives back 5, though the encoder is 256 counts off


@pytest.mark.parametrize("tick_us", [50, 100, 5000, 10000])
def test_every_tick_initialises_and_settles_a_move(tick_us):
    """--tick-us 50, 100, 5000, 10000: power-up scales the schedule; I and P-1B86 succeed."""
    station, ctl, plant, loop, result = station_rig(tick_us)
    assert result.ok, result.message
    sched = ctl.schedule()
    assert abs(sched.move_ns - 48 * MS) <= max(tick_us * 1000, 4 * MS)  # 002's periods kept
    taken, bound = supervised_move(station, ctl, loop, TARGET)
    assert station.fault is None and taken <= bound
    assert abs(signed(ctl.position()) - TARGET) <= AT_TARGET_COUNTS
    assert abs(plant.x - TARGET) <= AT_TARGET_COUNTS + 2  # the claim against the sim's truth


def test_schedule_the_controller_cannot_serve_is_refused_with_the_reason():
    """Monitor C 42 01 at a 50 µs tick would make WATCHJAW blind: refused, RAM unchanged."""
    station, ctl, _plant, _loop, _result = station_rig(50)
    before = ctl.ram[SYSCLKPD]
    c = ctl.monitor.find_command("C")
    with pytest.raises(CommandError, match="less than two encoder counts") as exc:
        station.execute(ctl.monitor, c, c.parse(["42", "01"]))
    assert "nothing changed" in str(exc.value)
    assert ctl.ram[SYSCLKPD] == before
    with pytest.raises(CommandError, match=r"schedule values are 01\.\.FF"):
        station.execute(ctl.monitor, c, c.parse(["43", "00"]))


def test_monitor_c_warns_when_the_schedule_predicts_oscillation():
    """C 45 40 is stored, with a warning naming WTCHJWSPD ≫ MVJAWSPD; C 45 01 is not warned about."""
    rig = make_rig()
    c = rig.ctl.monitor.find_command("C")
    lines = rig.station.execute(rig.ctl.monitor, c, c.parse(["45", "40"]))
    assert lines[0] == "45 40" and rig.ctl.ram[WTCHJWSPD] == 0x40
    assert lines[1].startswith("warning: moves may oscillate: WTCHJWSPD 40 ≫ MVJAWSPD 0C")
    assert rig.station.execute(rig.ctl.monitor, c, c.parse(["45", "01"])) == ["45 01"]


def test_supervisor_flags_three_undamped_half_cycles_and_not_a_decaying_approach():
    """Sign changes with peaks that do not decay are oscillation; a decaying approach is not."""
    seen = []
    sup = jawmove.MoveSupervisor(type("C", (), {"now_ns": 0})(), lambda a, n: seen.append((a, n)),
                                 None)
    sup.arm(10**12)
    for side, peak in [(1, 900), (-1, 200), (1, 50)]:  # decaying: a normal approach
        sup.flip(side, peak)
    sup.flip(-1, 30)
    assert seen == [] and sup.active
    sup.arm(10**12)
    for side, peak in [(1, 100), (-1, 90), (1, 95)]:
        sup.flip(side, peak)
    sup.flip(-1, 30)
    assert seen == [(100, 3)] and not sup.active


SCHEDULE = st.integers(1, 0xFF)


@settings(max_examples=20, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(tick_us=st.sampled_from([50, 100, 250, 1000, 2000, 5000, 10000]),
       sysclkpd=SCHEDULE, mvjawspd=SCHEDULE, sensorpd=SCHEDULE, wtchjwspd=SCHEDULE,
       target=st.integers(-0x2A00, 0))
def test_every_schedule_settles_stops_short_truthfully_or_trips_within_the_bound(
        tick_us, sysclkpd, mvjawspd, sensorpd, wtchjwspd, target):
    """Any SYSCLKPD/MVJAWSPD/SENSORPD/WTCHJWSPD 01..FF at any tick: refused when set, or the
    P move ends within its bound (settled, stopped short as wait says, or a fault), current zero."""
    station, ctl, plant, loop, result = station_rig(tick_us)
    assert result.ok, result.message
    c = ctl.monitor.find_command("C")
    for addr, value in ((SYSCLKPD, sysclkpd), (MVJAWSPD, mvjawspd), (SENSORPD, sensorpd),
                        (WTCHJWSPD, wtchjwspd)):
        try:
            station.execute(ctl.monitor, c, c.parse([f"{addr:02X}", f"{value:02X}"]))
        except CommandError as exc:
            assert "refused" in str(exc) and "nothing changed" in str(exc)
    sched = ctl.schedule()
    assert isinstance(sched, Schedule)
    taken, bound = supervised_move(station, ctl, loop, target)
    assert station.plant.board.dac == 0x80 and not ctl.moving
    if station.fault is None:
        assert taken <= bound + tick_us * 1000
        assert station.last_move is not None
        report = station.last_move.report[0]
        error = signed(ctl.position()) - target
        if report.startswith("at target"):
            assert abs(error) <= AT_TARGET_COUNTS
            assert abs(plant.x - target) <= AT_TARGET_COUNTS + 3  # the sim's truth agrees
        else:
            assert report.startswith("stopped ") and f"by {abs(error)} counts" in report
    else:
        assert station.fault.source in ("P move", "stall watchdog")
        assert taken <= max(bound, ctl.stall_limit_ns) + 2 * tick_us * 1000
