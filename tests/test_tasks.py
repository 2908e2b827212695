"""The self-scheduling routines: declared by their components, registered from the tree, one module each."""

from __future__ import annotations

import subprocess
import sys
import threading
import time
import types

import pytest
from _gripper_rig import make_rig
from _manipulator_rig import make_station

from pyrt.boards.gripper import DAC_NULL, LED_HI, LED_LO, P8155_PA, P8155_PB, P8155_PC
from pyrt.boards.i8031 import (
    COMMAND_CNT,
    DRVON,
    ENCODER_CNT,
    ERROR_CNT,
    FLAGS,
    MVJAWSPD,
    MXNJSPD,
    MXPJSPD,
    OLD_ENC,
    OTHER,
    PROX,
    RATE,
    SENSORPD,
    STOPCNT,
    STOPPED,
    WTCHJWSPD,
)
from pyrt.component import Component, walk
from pyrt.db import copy_station
from pyrt.errors import ConfigError
from pyrt.robots import axis as robot_axis
from pyrt.robots.pattern import PatternLog, log_writer, run_pattern
from pyrt.robots.stops import StopReason, StopRecord
from pyrt.scheduler import Loop, ReadyQueue, Task, WallClock, install
from pyrt.station.manipulator import ManipulatorStation
from pyrt.tasks import SyncWriter, ThreadWriter, axis_poll, jawmove, jawwatch, sensors, tasks_of

WAIT = "WAIT"  # the ready queue's own routine (002's wait), not a component's task


def _queue_routines(queue: ReadyQueue) -> list[tuple[str, int]]:
    return [(r.name, r.address) for r in queue.routines if r.name != WAIT]


# -- declarations and the station's queue --------------------------------------------------


def test_gripper_declares_its_three_routines_at_their_appendix_b_addresses():
    """The gripper controller declares MVJAWS 04C2, SENSORS 0473, WATCHJAW 0541, periods from RAM 43/44/45."""
    rig = make_rig()
    ctl = rig.ctl
    decl = ctl.tasks()
    assert [(t.name, t.address) for t in decl] == [
        ("MVJAWS", 0x04C2), ("SENSORS", 0x0473), ("WATCHJAW", 0x0541)]
    assert [t.period_now() for t in decl] == [0x0C, 0x0A, 0x01]
    ctl.ram[MVJAWSPD], ctl.ram[SENSORPD], ctl.ram[WTCHJWSPD] = 0x20, 0x21, 0x02
    assert [t.period_now() for t in decl] == [0x20, 0x21, 0x02]
    assert all(t.first is None for t in decl)  # power_up schedules them, as 002's main program


def test_gripper_station_queue_holds_exactly_the_declared_tasks():
    """The gripper station's ready queue holds exactly the tree's tasks; after power-up Q holds their addresses."""
    rig = make_rig()
    station = rig.station
    declared = tasks_of(station.root)
    assert [(t.name, t.address) for t in declared] == _queue_routines(rig.ctl.queue)
    assert [c for c in walk(station.root) if c.tasks()] == [rig.ctl]  # the monitor declares none
    assert rig.ctl.queue.pending() == ["MVJAWS", "SENSORS", "WATCHJAW"]
    queue = rig.ctl.queue
    for t in declared:
        assert queue.routine(t.address).period() == t.period_now()


def test_manipulator_declares_polyaxis_and_axes_polls(tmp_path):
    """The PolyAxis declares POLYAXIS 0100 every 50 checks and AXES 0101 every 10 (1 ms tick); nothing else declares tasks."""
    station, _ = make_station(tmp_path, tick_ns=1_000_000)
    try:
        pa = station.polyaxis
        decl = pa.tasks()
        assert [(t.name, t.address, t.period_now(), t.first) for t in decl] == [
            ("POLYAXIS", 0x0100, 50, 50), ("AXES", 0x0101, 10, 10)]
        assert [c for c in walk(pa) if c.tasks()] == [pa]
        assert [(t.name, t.address) for t in tasks_of(pa)] == _queue_routines(station.queue)
        assert sorted(station.queue.pending()) == ["AXES", "POLYAXIS"]
    finally:
        station.close()


def test_polyaxis_task_periods_must_be_set_and_in_range(tmp_path):
    """A PolyAxis refuses periods outside 1..255 checks; without periods it cannot declare its tasks."""
    station, _ = make_station(tmp_path)
    try:
        pa = station.polyaxis
        with pytest.raises(ValueError, match=r"1\.\.255"):
            pa.set_task_periods(0, 10)
        with pytest.raises(ValueError, match=r"1\.\.255"):
            pa.set_task_periods(10, 256)
        saved, pa.task_periods = pa.task_periods, None
        with pytest.raises(ConfigError, match="set_task_periods"):
            pa.tasks()
        pa.task_periods = saved
    finally:
        station.close()


def test_component_declares_no_tasks_by_default():
    """A bare component declares none."""
    assert Component().tasks() == []


# -- install ----------------------------------------------------------------------------------


def test_install_schedules_first_runs_and_passes_the_tick_time():
    """install registers every task, schedules those with a first run, and calls a timed body with the queue's time."""
    q = ReadyQueue(capacity=4)
    seen: list[int] = []
    calls: list[str] = []
    install(q, [Task("A", 0x10, seen.append, 2, first=3, timed=True),
                Task("B", 0x11, lambda: calls.append("B"), 1)])
    assert q.pending() == ["A"]
    for t in range(1, 8):
        q.tick(t * 1000)
    assert seen == [3000, 5000, 7000]
    assert calls == []  # B has no first run: its owner schedules it
    with pytest.raises(ValueError, match="first run"):
        install(ReadyQueue(capacity=2), [Task("C", 0x12, lambda: None, 1, first=300)])


# -- the routine modules ----------------------------------------------------------------------


def test_task_modules_do_not_import_robots():
    """Importing every routine module loads nothing of pyrt.robots (robots import tasks, never the reverse)."""
    code = ("import sys\n"
            "import pyrt.tasks.sensors, pyrt.tasks.jawmove, pyrt.tasks.jawwatch\n"
            "import pyrt.tasks.polyaxis_poll, pyrt.tasks.axis_poll, pyrt.tasks.writeback\n"
            "bad = sorted(m for m in sys.modules if m.startswith(('pyrt.robots', 'pyrt.sim')))\n"
            "assert not bad, bad\n")
    subprocess.run([sys.executable, "-c", code], check=True)


class FakeCPU:
    """The external data space: port reads from a dict, writes recorded."""

    def __init__(self, ports: dict[int, int]):
        self.ports = ports
        self.writes: list[tuple[int, int]] = []

    def movx_read(self, addr: int) -> int:
        return self.ports[addr]

    def movx_write(self, addr: int, byte: int) -> None:
        self.writes.append((addr, byte))


class FakeController:
    """The least a gripper routine needs: a RAM image, a CPU, drive(), job, last_stop."""

    def __init__(self, ports: dict[int, int] | None = None):
        self.ram = bytearray(128)
        self.cpu = FakeCPU(ports or {P8155_PC: 0x03})  # both jog bits high: no jog
        self.job = None
        self.last_stop = ""
        self.driven: list[int] = []
        self.supervisor = jawmove.MoveSupervisor(None, None, None)

    def drive(self, byte: int) -> None:
        self.driven.append(byte)

    def move_ended(self, why: str) -> None:
        self.last_stop = why

    def set_word(self, addr: int, value: int) -> None:
        self.ram[addr] = value & 0xFF
        self.ram[addr + 1] = (value >> 8) & 0xFF

    def word(self, addr: int) -> int:
        return self.ram[addr] | (self.ram[addr + 1] << 8)


def test_mvjaws_drives_the_ram_error_then_ends_stopcnt_bumps_after_the_stopped_bit():
    """002: with the drive bit, current = -ERROR_CNT as WATCHJAW left it (excess-128, clipped); after the stopped bit the counter runs down, then the current is nulled and the drive bit cleared."""
    ctl = FakeController()
    ram = ctl.ram
    ram[MXPJSPD], ram[MXNJSPD] = 0x80 + 0x7F, 0x80 - 0x7F
    ctl.set_word(COMMAND_CNT, -0x10)
    ctl.set_word(ENCODER_CNT, -0x30)
    ctl.set_word(ERROR_CNT, 0x80 - 0x20)  # WATCHJAW's error: 32 counts short
    ram[FLAGS] = 1 << DRVON
    ram[STOPCNT] = 2
    jawmove.mvjaws(ctl)
    assert ctl.driven == [0x80 + 0x20]  # 32 counts to go, opening: +32 in excess-128
    ctl.set_word(ENCODER_CNT, -0x1000)  # far away, but WATCHJAW has not run: same error
    jawmove.mvjaws(ctl)
    assert ctl.driven[-1] == 0x80 + 0x20
    ctl.set_word(ERROR_CNT, (0x80 - 0x1000 + 0x10) & 0xFFFF)  # now it has: clipped
    jawmove.mvjaws(ctl)
    assert ctl.driven[-1] == 0xFF
    ram[FLAGS] |= 1 << STOPPED
    jawmove.mvjaws(ctl)
    assert ram[STOPCNT] == 1 and ram[FLAGS] & (1 << DRVON)
    jawmove.mvjaws(ctl)
    assert ctl.driven[-1] == DAC_NULL and not ram[FLAGS] & (1 << DRVON)
    assert ram[STOPCNT] == 0 and ctl.last_stop == "stopped"
    n = len(ctl.driven)
    jawmove.mvjaws(ctl)  # drive bit off, no jog: nothing happens
    assert len(ctl.driven) == n


def test_mvjaws_jog_drives_at_the_limit_and_the_target_follows():
    """002: a jog request drives the motor in its direction and returns; the target follows the jaws."""
    ctl = FakeController({P8155_PC: 0x02})  # bit 0 low: jog open
    ram = ctl.ram
    ram[MXPJSPD], ram[MXNJSPD] = 0xA0, 0x60
    ctl.set_word(ENCODER_CNT, 0xFF00)
    jawmove.mvjaws(ctl)
    assert ctl.driven == [0xA0]
    assert ctl.word(COMMAND_CNT) == 0xFF00
    ctl.cpu.ports[P8155_PC] = 0x03  # released: the jog is ended with a null current
    jawmove.mvjaws(ctl)
    assert ctl.driven[-1] == DAC_NULL and ctl.last_stop == "jog ended"


def test_watchjaw_sets_stopped_rate_and_excess_128_error():
    """002: WATCHJAW compares the position with the previous one, sets the stopped bit when equal, and computes the error."""
    ctl = FakeController()
    ram = ctl.ram
    ctl.set_word(ENCODER_CNT, 0x0105)
    ctl.set_word(OLD_ENC, 0x0100)
    ctl.set_word(COMMAND_CNT, 0x0100)
    jawwatch.watchjaw(ctl)
    assert ctl.word(RATE) == 5 and not ram[FLAGS] & (1 << STOPPED)
    assert ctl.word(ERROR_CNT) == 0x0085 and ctl.word(OLD_ENC) == 0x0105
    jawwatch.watchjaw(ctl)
    assert ctl.word(RATE) == 0 and ram[FLAGS] & (1 << STOPPED)


def test_sensors_reads_the_ports_into_ram_and_shows_them():
    """002: SENSORS reads the proximity and other sensors into 2D/2E and lights the LEDs."""
    ctl = FakeController({P8155_PA: 0x5A, P8155_PB: 0xFB})
    sensors.sensors(ctl)
    assert ctl.ram[PROX] == 0x5A and ctl.ram[OTHER] == 0xFB
    assert ctl.cpu.writes == [(LED_LO, 0x5A), (LED_HI, 0xFB)]


def test_axis_poll_skips_axes_under_polyaxis_control():
    """AXES polls the standalone axes only, with the tick time in seconds."""

    class A:
        def __init__(self, mode: str):
            self.mode = mode
            self.polled: list[float] = []
            self.motor = types.SimpleNamespace(running=False)  # at rest: nothing to supervise

        def poll(self, now_s: float) -> None:
            self.polled.append(now_s)

    free, driven = A(axis_poll.STANDALONE), A(axis_poll.POLYAXIS)
    axis_poll.axis_poll([free, driven], 2_500_000_000)
    assert free.polled == [2.5] and driven.polled == []
    assert robot_axis.POLYAXIS == axis_poll.POLYAXIS  # one mode word for both


# -- the pattern log off the loop thread ------------------------------------------------------


class Walker:
    """A robot that reaches every endpoint in one step (for the pattern job)."""

    name = "walker"

    def __init__(self):
        self.active = False
        self.position = (0.0, 0.0, 0.0)
        self.last_stop: StopRecord | None = None

    def to(self, target):
        self.active = True
        self.position = tuple(target)
        self.last_stop = StopRecord(StopReason.ENDPOINT_STOP, "at the endpoint", self.position,
                                    0.0, self.position)
        self.active = False


def test_pattern_log_is_written_by_the_writer_thread(tmp_path):
    """With the thread writer the pattern log is appended on the writer's thread, never the job's, in order."""
    path = tmp_path / "p.log"
    threads: list[str] = []

    class Watched(PatternLog):
        def write_back(self, changes):
            threads.append(threading.current_thread().name)
            super().write_back(changes)

    clock = [0.0]
    job = run_pattern(Walker(), [(1.0, 0.0, 0.0), (2.0, 0.0, 0.0)],
                      lambda: ThreadWriter(Watched(path), what="pattern log"),
                      lambda: clock[0], pause_s=1.0)
    with pytest.raises(StopIteration) as done:
        while True:
            next(job)
            clock[0] += 0.5
    assert len(done.value.value) == 2
    deadline = time.monotonic() + 30  # a bound for a hang only
    while not path.exists() or not path.read_text().endswith("# pattern complete\n"):
        assert time.monotonic() < deadline, "the writer thread never wrote the log"
        time.sleep(0.01)
    lines = path.read_text().splitlines()
    assert lines[0] == "# pattern of 2 endpoints, walker"
    assert [ln.split()[0] for ln in lines[1:3]] == ["1", "2"]
    assert threads and threading.current_thread().name not in threads


def test_the_polyaxis_is_constructed_whole_and_owns_its_poll(tmp_path):
    """The station passes the PolyAxis everything at construction; polyaxis-poll only calls its poll."""
    from pyrt.robots.polyaxis import PolyAxisServices
    from pyrt.station.manipulator import ManipulatorStation

    station = ManipulatorStation(copy_station("prototype", tmp_path / "p"), tick_ns=1_000_000)
    try:
        pa = station.polyaxis
        assert pa.motion is station.motion and pa.spawn == station.loop.spawn
        assert pa.pattern_writer == "sync" and pa.task_periods == (50, 10)
        assert pa.on_stop == [station.stops.append, station._stopped]
        with pytest.raises(ConfigError, match="pattern writer"):
            PolyAxisServices(pattern_writer="later")
        seen = []
        pa.poll = seen.append  # the task hands the tick time to the controller's poll
        pa.tasks()[0].fn(2_500_000_000)
        assert seen == [2.5]
    finally:
        station.close()


def test_pattern_log_writer_kinds_follow_the_clock(tmp_path):
    """The pattern log is written on a thread on a wall clock and at once on a simulated clock (deterministic)."""
    a, b = log_writer(tmp_path / "a.log", "thread"), log_writer(tmp_path / "b.log", "sync")
    try:
        assert isinstance(a, ThreadWriter) and isinstance(b, SyncWriter)
    finally:
        a.close()
    with pytest.raises(ValueError, match="sync"):
        log_writer(tmp_path / "c.log", "later")
    sim, _ = make_station(tmp_path / "sim")
    wall = ManipulatorStation(copy_station("prototype", tmp_path / "wall"),
                              loop=Loop(WallClock(), period_ns=1_000_000))
    try:
        assert sim.polyaxis.pattern_writer == "sync"
        assert wall.polyaxis.pattern_writer == "thread"
    finally:
        sim.close()
        wall.close()
