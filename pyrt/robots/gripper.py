"""The parallel-jaw gripper controller of 002 on the pyrt scheduler.

The 8031's on-chip RAM image *is* the controller's state: the ready queue
lives in it (T at 2F, Q at 35, SYSCLKCNT/SYSCLKPD at 41/42), the three
self-scheduling routines read their periods from it (43-45) and keep their
variables in it (Appendix A), so whatever the monitor shows is the real
state and whatever it changes takes effect.  The routines' bodies live in
:mod:`pyrt.tasks` (``sensors``, ``jawmove``, ``jawwatch``); the controller
declares them (:meth:`GripperController.tasks`) at their EPROM addresses of
Appendix B, so Q holds 04C2, 0473 and 0541.

Everything here runs in the loop's thread: the routines from the ready
queue, the encoder interrupt handlers from the board, the main-program
sequences (``init``/``fullopen``, the ``C`` calibration) as foreground jobs,
and the command entry points when a console calls them through the runner.

The controller is three parts, one module each:

* :mod:`pyrt.robots.gripper_ram`: the view of the 8031's RAM (words,
  bits, the monitor's bytes, the schedule variables as periods);
* :mod:`pyrt.robots.jaw_supervision`: pyrt's supervision of every move
  (settle and stall bounds, oscillation, the stall watchdog, the schedule
  values it refuses or warns about);
* this module: the controller proper (power-up, the interrupt handlers,
  the routines, the main-program sequences, the reflex and what the ``CMD:``
  letters of :mod:`pyrt.robots.gripper_commands` and the monitor call).

Safety (002's central fix, kept and extended): drive current is never left
applied without movement.  ``fullopen`` aborts when the jaws stop before
the limit bit; a commanded move ends STOPCNT bumps after the stopped bit; a
jog held against a stop is cut off the same way; and pyrt supervises
every commanded move, independently of the RAM (which the monitor can
change; :class:`~pyrt.robots.jaw_supervision.JawSupervision`).  A fault's
reflex action nulls the DAC and clears the drive bit in the same tick.
"""

from __future__ import annotations

from collections.abc import Generator
from dataclasses import dataclass
from functools import partial
from typing import Any

from pyrt.boards.gripper import (
    DAC,
    DAC_NULL,
    LED_HI,
    LED_LO,
    P8155_CMD,
)
from pyrt.boards.i8031 import (
    COMMAND_CNT,
    ENCODER_CNT,
    ERROR_CNT,
    FLAGS,
    I8031,
    JSPEED,
    MVJAWSPD,
    MXNJSPD,
    MXPJSPD,
    OLD_ENC,
    OTHER,
    PROX,
    RATE,
    SEMA,
    SENSORPD,
    STOPCNT,
    SYSCLKCNT,
    SYSCLKPD,
    VECTOR_EXT0,
    VECTOR_EXT1,
    WTCHJWSPD,
    Q,
    T,
)
from pyrt.component import Component, Signal
from pyrt.errors import CommandError
from pyrt.robots.gripper_commands import (
    SP_CMDLOOP,
    CommandLetters,
    GripperMonitor,
    parse_hex,
    parse_target,
)
from pyrt.robots.gripper_ram import (
    DEFAULT_SYSCLKPD,
    ENC16,
    MASK_DOJOG,
    MASK_DRVON,
    MASK_JOGSTALL,
    MASK_STOPPED,
    GripperRam,
    Schedule,
)
from pyrt.robots.jaw_supervision import JawSupervision
from pyrt.scheduler import ByteImage, ByteRef, Job, Loop, RateGroup, ReadyQueue, Task, install
from pyrt.scheduler.motion import MotionRecord, MotionType, register_motion_type
from pyrt.scope import Source
from pyrt.tasks import jawmove, jawwatch, sensors
from pyrt.tasks.jawmove import STOPBUMPS, MoveSupervisor

__all__ = [
    "ADDR_MVJAWS",
    "ADDR_SENSORS",
    "ADDR_SYSCLK",
    "ADDR_WATCHJAW",
    "GripperController",
    "JawCalibration",
    "JobResult",
    "Schedule",
]

# Appendix B: EPROM addresses of the self-scheduling routines and the clock handler.
ADDR_SYSCLK = 0x0295
ADDR_MVJAWS = jawmove.ADDRESS  # 04C2
ADDR_SENSORS = sensors.ADDRESS  # 0473
ADDR_WATCHJAW = jawwatch.ADDRESS  # 0541

#: 002: "a speed value of 7F is used" with the original worm/sector gears.
DEFAULT_JSPEED = 0x7F
#: 8155 command: ports A, B and C all input, timer stopped.
MODE_8155 = 0x00
#: Queue checks fullopen and the calibration give the motor to get going
#: before they believe the stopped bit (002: a stale stopped bit at the
#: start aborts the initialization; a large WTCHJWSPD still does, as 002 says).
START_GRACE = 4
START_GRACE_NS = 16_000_000
#: Upper bound on any foreground drive, in queue checks (60 s at the defaults).
MAX_DRIVE_CHECKS = 15000

# The FLAGS bits the reflex and the sequences clear (named here as before).
_MASK_DRVON = MASK_DRVON
_MASK_DOJOG = MASK_DOJOG


@dataclass(frozen=True)
class JawCalibration:
    """What the station knows of the mechanism: counts from wide open to
    closed and the opening in mm there (for mm beside counts), and how fast
    the worm turns (counts/s per current unit above a friction deadband),
    for the supervision's bounds.  The defaults are the simulated jaws'."""

    closed: int = 0x2A00
    open_mm: float = 76.0
    gain: float = 20.0
    deadband: int = 8

    def mm(self, counts: int) -> float:
        """Jaw opening in mm at encoder ``counts`` (0 wide open, negative closing)."""
        return self.open_mm * (1.0 + counts / self.closed)

    def counts(self, mm: float) -> int:
        """Encoder counts where the opening is ``mm``."""
        return round(-(self.open_mm - mm) / self.open_mm * self.closed)

    def speed(self, jspeed: int) -> float:
        """Jaw speed (counts/s) at a current of ``jspeed`` units (at least 1 count/s)."""
        return max(1.0, (jspeed - self.deadband) * self.gain)


@dataclass(frozen=True)
class JobResult:
    """How a main-program sequence ended: ``ok``, a message, and a value if any."""

    ok: bool
    message: str
    value: int | None = None


def _attach_clock(loop: Loop, queue: ReadyQueue, clock_ns: int | None) -> None:
    """The clock interrupt ``SYSCLK`` on ``loop``: ticking with the loop (None, as on
    002's board), or a rate group of its own every ``clock_ns``."""
    if clock_ns is None:
        loop.attach(queue, name="SYSCLK")
        return
    group = RateGroup("SYSCLK", period_ns=clock_ns)
    group.attach(queue, name="SYSCLK")
    loop.attach(group)


class GripperController(Component, CommandLetters):
    """The 002 controller program over an :class:`~pyrt.boards.i8031.I8031`.

    A :class:`~pyrt.component.Component`: its signals are the RAM variables
    of Appendix A by name, its commands the ``CMD:`` letters, its child the
    monitor, its tasks the three self-scheduling routines (:meth:`tasks`),
    its reflex nulls the drive current and clears the drive and jog bits.
    Its parts: :attr:`mem`, the view of the RAM; :attr:`supervision`, the
    supervision of every move.

    ``cpu`` must have the gripper board mapped in its external data space
    (a :class:`~pyrt.boards.gripper.GripperBoard` over any back end).  Call
    :meth:`attach` to put the ready queue (with the tasks) and the stall
    watchdog on a loop (after the plant), then :meth:`power_up`, then
    :meth:`start_init`.
    """

    #: Back at ``CMD:`` from the monitor (the letters' own, not Component's default).
    enter_level = CommandLetters.enter_level
    params = CommandLetters.params

    def __init__(self, cpu: I8031, name: str = "gripper", stall_limit_ns: int = 1_000_000_000,
                 calibration: JawCalibration | None = None):
        self.name = name
        #: The mechanism's numbers (mm, speed) the bounds and the mm display use.
        self.calibration = calibration if calibration is not None else JawCalibration()
        self.cpu = cpu
        self.ram = cpu.ram
        self._loop: Loop | None = None
        self._clock_ns = 0  # the clock interrupt's own period (0: the loop's tick)
        #: The RAM as the controller reads and writes it (words, bits, schedule).
        self.mem = GripperRam(self.ram, self._tick_ns)
        self.monitor = GripperMonitor(self)
        #: pyrt's supervision of every move (bounds, oscillation, stall watchdog).
        self.supervision = JawSupervision(self, self.mem, stall_limit_ns)
        # the RAM's words as the routines and the monitor name them here
        self.word = self.mem.word
        self._sword = self.mem.sword
        self._set_word = self.mem.set_word
        self.queue = ReadyQueue(
            capacity=6,
            divisor=DEFAULT_SYSCLKPD,
            image=ByteImage(self.ram, T, Q, SYSCLKCNT, SYSCLKPD, sema=(FLAGS, SEMA)),
            name=name,
        )
        #: Encoder interrupts seen (a one-element list: the handlers' counter).
        self._pulse_cell = [0]
        self._isr_up = self._make_isr(+1)
        self._isr_down = self._make_isr(-1)
        cpu.set_vector(VECTOR_EXT0, self._isr_up)
        cpu.set_vector(VECTOR_EXT1, self._isr_down)
        #: The foreground job (init, calibration) in progress, if any.
        self.job: Job | None = None
        self._dac = DAC_NULL
        #: Why the last commanded move or jog ended, for the console's ``wait``.
        self.last_stop = ""
        #: The running move's supervision (armed by :meth:`move`).
        self.supervisor: MoveSupervisor = self.supervision.supervisor
        #: Where the last commanded move started, counts (its direction, for ``wait``).
        self.move_from = 0

    # -- wiring ------------------------------------------------------------------

    def _tick_ns(self) -> int:
        """The clock interrupt's period (ns): its rate group's, else the loop's tick."""
        if self._clock_ns:
            return self._clock_ns
        return self._loop.period_ns if self._loop is not None else 1_000_000

    def attach(self, loop: Loop, *, register: bool = True, clock_ns: int | None = None) -> None:
        """Attach the clock interrupt (ready queue) and the stall watchdog to ``loop``.

        With ``register`` (a controller used on its own) its :meth:`tasks` go
        on its ready queue too; a station registers them from its component
        tree instead and passes ``register=False``.  ``clock_ns``: the clock
        interrupt's period, a rate group ``SYSCLK`` of its own whatever the
        loop's tick (None: the queue ticks with the loop, as on 002's board)."""
        if register:
            install(self.queue, self.tasks())
        self._loop = loop
        self.supervisor.clock = loop
        _attach_clock(loop, self.queue, clock_ns)
        self._clock_ns = clock_ns or 0
        loop.attach(self.watchdog, name="stall watchdog")

    def power_up(self) -> None:
        """What the main program does first: null the drive, reset SP, load
        the schedule values and RAM variables, start the three routines."""
        ram = self.ram
        self.drive(DAC_NULL)
        self.cpu.sp = SP_CMDLOOP
        for addr, value in self.power_up_schedule().items():
            ram[addr] = value
        ram[FLAGS] = 0
        ram[PROX] = ram[OTHER] = 0xFF
        self.mem.set_speed(DEFAULT_JSPEED)
        self.mem.zero_counts()
        ram[STOPCNT] = 0
        q = self.queue
        q.interrupts_enabled = True
        q.clear()
        q.resume(restart=False)
        q.schedule(ADDR_MVJAWS, ram[MVJAWSPD])
        q.schedule(ADDR_SENSORS, ram[SENSORPD])
        q.schedule(ADDR_WATCHJAW, ram[WTCHJWSPD])

    def power_up_schedule(self) -> dict[int, int]:
        """The schedule values power-up loads (:meth:`GripperRam.power_up_schedule`)."""
        return self.mem.power_up_schedule()

    # -- the schedule and the supervision (the parts') -------------------------------

    def schedule(self) -> Schedule:
        """The routines' periods as the RAM and the loop's tick make them now."""
        return self.mem.schedule()

    def stall_bound_ns(self) -> int:
        """How long current may be held on jaws that do not move (the supervision's)."""
        return self.supervision.stall_bound_ns()

    @property
    def stall_limit_ns(self) -> int:
        """The stall bound is never more than this (ns)."""
        return self.supervision.stall_limit_ns

    @property
    def settle_bound_s(self) -> float:
        """The settle bound of the running move, seconds."""
        return self.supervision.settle_bound_s

    def schedule_warning(self, addr: int, value: int) -> str | None:
        """Monitor ``C``: the supervision's refusal or warning for a schedule value."""
        return self.supervision.schedule_warning(addr, value)

    def move_ended(self, why: str) -> None:
        """MVJAWS (or a jog) ended the commanded move: say why, stop supervising
        (:meth:`JawSupervision.ended`: a move the stopped bit ended short says so)."""
        self.last_stop = self.supervision.ended(why)

    # -- registers -----------------------------------------------------------------

    def drive(self, byte: int) -> None:
        """Write the DAC (excess-128 current byte) and remember it."""
        self._dac = byte
        self.cpu.movx_write(DAC, byte)

    @property
    def dac(self) -> int:
        """The last byte written to the DAC (latched by the hardware)."""
        return self._dac

    # -- interrupt handlers (HHMVJAWS.51) ----------------------------------------

    def encoder_up(self) -> None:
        """External request 0: one encoder count up."""
        self._isr_up()

    def encoder_down(self) -> None:
        """External request 1: one encoder count down."""
        self._isr_down()

    def _make_isr(self, delta: int):
        """The handler installed at the vector: the same work as
        :meth:`encoder_up`/:meth:`encoder_down` with every name bound local
        (it runs once per encoder count, several times a tick)."""
        w = self.mem.w16
        pulses = self._pulse_cell

        def isr() -> None:
            w[ENC16] = (w[ENC16] + delta) & 0xFFFF
            pulses[0] += 1

        return isr

    # -- the self-scheduling routines (pyrt.tasks: sensors, jawmove, jawwatch) --------

    def tasks(self) -> list[Task]:
        """MVJAWS, SENSORS and WATCHJAW at their Appendix B addresses, their
        periods read from RAM 43/44/45 at every reschedule (monitor ``C 43 ..``
        takes effect); :meth:`power_up` schedules them, as 002's main program."""
        ram = self.ram
        return [
            Task(jawmove.NAME, ADDR_MVJAWS, partial(jawmove.mvjaws, self),
                 ByteRef(ram, MVJAWSPD)),
            Task(sensors.NAME, ADDR_SENSORS, partial(sensors.sensors, self),
                 ByteRef(ram, SENSORPD)),
            Task(jawwatch.NAME, ADDR_WATCHJAW, partial(jawwatch.watchjaw, self),
                 ByteRef(ram, WTCHJWSPD)),
        ]

    # -- safety ----------------------------------------------------------------------

    def reflex(self) -> None:
        """The reflex action: null the current, clear drive and jog, abandon
        the foreground job.  Runs in the tick that found the fault (or the stop).
        The controller's own state is cleared whatever the DAC write does (a
        dead link raises BoardError after it)."""
        try:
            self.drive(DAC_NULL)
        finally:
            self._dac = DAC_NULL
            self.supervisor.disarm()
            if self.mem.clear_drive():
                self.last_stop = "stopped by the reflex (move abandoned)"
            if self.job is not None:
                self.job.cancel()
                self.job = None

    def watchdog(self, now_ns: int) -> None:
        """Every tick: the stall watchdog and the settle bound of the running
        move (:meth:`JawSupervision.watchdog`)."""
        self.supervision.watchdog(now_ns, self._dac, self._pulse_cell[0])

    # -- main-program sequences (foreground jobs) ------------------------------------

    def start_init(self) -> Job:
        """Start ``I``: init + fullopen, as a foreground job (result: :class:`JobResult`)."""
        return self._spawn("init", self._init())

    def start_calibration(self) -> Job:
        """Start ``C``: init, close until stopped, read the count, init again."""
        return self._spawn("calibrate", self._calibrate_job())

    def _spawn(self, name: str, gen: Generator[None, None, JobResult]) -> Job:
        if self._loop is None:
            raise CommandError("controller is not attached to a loop")
        if self.job is not None and not self.job.done:
            raise CommandError(f"busy: {self.job.name} in progress")
        if not self.queue.interrupts_enabled:
            raise CommandError(
                f"{name} needs the clock interrupt, which is off (monitor I): M, I turns it on"
            )
        self.job = self._loop.spawn(name, self._run_job(gen))
        return self.job

    def _run_job(self, gen: Generator[None, None, JobResult]) -> Generator[None, None, JobResult]:
        try:
            result = yield from gen
        except Exception as exc:
            # a job that fails (a full ready queue, say) is a fault of the robot
            self.job = None
            self.fail(f"{type(exc).__name__}: {exc}", source="main program")
            return JobResult(False, f"{type(exc).__name__}: {exc}")
        finally:
            self.drive(DAC_NULL)  # a sequence never leaves current behind it
        self.job = None
        return result

    def _wait(self, n: int) -> Generator[None, None, None]:
        if not self.queue.interrupts_enabled:
            raise CommandError("clock interrupt is off (monitor I): the queue is frozen")
        yield from self.queue.wait(n & 0xFF)

    def _init(self) -> Generator[None, None, JobResult]:
        """HHINIT: init (8155, sensor bits, encoder variables), then fullopen."""
        ram = self.ram
        self.drive(DAC_NULL)
        ram[FLAGS] &= ~(MASK_DRVON | MASK_DOJOG | MASK_JOGSTALL) & 0xFF
        self.cpu.movx_write(P8155_CMD, MODE_8155)
        ram[PROX] = ram[OTHER] = 0xFF
        self.mem.zero_counts()
        ram[STOPCNT] = 0
        # wait for the 8155 to reset and for SENSORS to read the ports once
        yield from self._wait(ram[SENSORPD] + 1)
        return (yield from self._fullopen())

    def _grace(self) -> int:
        """START_GRACE queue checks, but never less than START_GRACE_NS of loop time
        (a faster tick than 1 ms would otherwise end the grace before the motor
        is up to speed)."""
        per_check = self._tick_ns() * (self.ram[SYSCLKPD] or 256) if self._loop else 0
        if per_check <= 0:
            return START_GRACE
        return min(255, max(START_GRACE, -(-START_GRACE_NS // per_check)))

    def _fullopen(self) -> Generator[None, None, JobResult]:
        """Drive the jaws wide open until the limit bit; abort if they stop first."""
        ram = self.ram
        if not self.mem.at_limit:
            self.drive(ram[MXPJSPD])
            yield from self._wait(self._grace())
            for _ in range(MAX_DRIVE_CHECKS):
                yield from self._wait(1)
                if self.mem.at_limit:
                    break
                if self.mem.stopped:
                    self.drive(DAC_NULL)
                    # the limit bit may be up to one SENSORS period old: look again
                    yield from self._wait(ram[SENSORPD] + 1)
                    if self.mem.at_limit:
                        break
                    return JobResult(
                        False,
                        "INIT FAILED: jaws stopped before the limit sensor fired "
                        f"(encoder {self.word(ENCODER_CNT):04X}); current nulled",
                    )
            else:
                self.drive(DAC_NULL)
                return JobResult(False, "INIT FAILED: limit sensor not reached in time")
        self.drive(DAC_NULL)
        yield from self._settle()
        self.mem.zero_counts()
        self.last_stop = "init"
        return JobResult(True, "jaws wide open (limit sensor on), encoder 0000", 0)

    def _settle(self) -> Generator[None, None, None]:
        for _ in range(MAX_DRIVE_CHECKS):
            yield from self._wait(1)
            if self.mem.stopped:
                return

    def _calibrate_job(self) -> Generator[None, None, JobResult]:
        first = yield from self._init()
        if not first.ok:
            return first
        ram = self.ram
        self.drive(ram[MXNJSPD])
        yield from self._wait(self._grace())
        for _ in range(MAX_DRIVE_CHECKS):
            yield from self._wait(1)
            if self.mem.stopped:
                break
        self.drive(DAC_NULL)
        yield from self._settle()
        closed = self.word(ENCODER_CNT)
        again = yield from self._init()
        if not again.ok:
            return JobResult(False, again.message, closed)
        return JobResult(True, f"{closed:04X}", closed)

    # -- commands (called in the loop thread) -------------------------------------

    @property
    def busy(self) -> bool:
        """A foreground job (init, calibration) is running."""
        return self.job is not None and not self.job.done

    @property
    def moving(self) -> bool:
        """A commanded move or a jog is in progress (drive or dojog bit)."""
        return self.mem.moving

    def move(self, target: int) -> None:
        """``P``: store the target and set the drive bit (target -8000..0000)."""
        if not -0x8000 <= target <= 0:
            raise CommandError(
                f"target {target:+X} refused: encoder counts are 0000 (wide open) or negative"
            )
        self.check_can_move()
        ram = self.ram
        self.move_from = self._sword(ENCODER_CNT)
        self._set_word(COMMAND_CNT, target)
        # pyrt: P also stores the error the new target makes and clears the
        # stopped bit.  Both are WATCHJAW's to keep, but until its next run
        # they tell of the jaws before this move: with a large WTCHJWSPD,
        # MVJAWS would drive towards the old target and count STOPCNT down
        # on a stopped bit older than the move (002: it counts "after the
        # stopped bit goes on"), ending the move where it stands.
        self._set_word(ERROR_CNT, (self.word(ENCODER_CNT) - target + 0x80) & 0xFFFF)
        ram[STOPCNT] = STOPBUMPS
        ram[FLAGS] = (ram[FLAGS] & ~(MASK_DOJOG | MASK_STOPPED) | MASK_DRVON) & 0xFF
        self.last_stop = ""
        now = self._loop.now_ns if self._loop is not None else 0
        self.supervision.arm(now, target - self._sword(ENCODER_CNT))

    def check_can_move(self) -> None:
        """Raise CommandError unless a move may start now (no foreground job;
        the station refuses every move while the robot is faulted)."""
        if self.busy:
            raise CommandError(f"busy: {self.job.name} in progress")  # type: ignore[union-attr]

    def set_speed(self, speed: int) -> str:
        """``X``: the maximum jaw speed (01..7F), as JSPEED, MXPJSPD, MXNJSPD;
        returns what it changed."""
        if not 1 <= speed <= 0x7F:
            raise CommandError(f"speed {speed:02X} is out of range (01..7F)")
        ram = self.ram
        old = ram[JSPEED]
        self.mem.set_speed(speed)
        line = (f"speed {old:02X} -> {speed:02X}: JSPEED {speed:02X}, MXPJSPD {ram[MXPJSPD]:02X}, "
                f"MXNJSPD {ram[MXNJSPD]:02X} (up to {self.calibration.speed(speed):.0f} counts/s)")
        if speed <= self.calibration.deadband:
            line += (f"; warning: at or below the worm's friction ({self.calibration.deadband:02X})"
                     ": the jaws will not move")
        elif self.schedule().watch_ns * self.calibration.speed(speed) < 2e9:
            line += (f"; warning: WATCHJAW (every {self.schedule().watch_ns / 1e6:g} ms) sees "
                     "less than two counts at this speed: the stopped bit may end moves short")
        return line

    def replaces_target(self) -> bool:
        """A commanded move runs (drive bit on, no jog): a new P changes its target."""
        return bool(self.ram[FLAGS] & MASK_DRVON) and not self.busy

    def target(self) -> int:
        """``T``: COMMAND_CNT."""
        return self.word(COMMAND_CNT)

    def position(self) -> int:
        """``W``: ENCODER_CNT."""
        return self.word(ENCODER_CNT)

    def error(self) -> int:
        """``E``: ERROR_CNT (excess-128 word)."""
        return self.word(ERROR_CNT)

    def sensor_word(self) -> int:
        """``S``: the sensor word, 2E high byte, 2D low byte."""
        return self.word(PROX)

    # -- monitor (called in the loop thread) -------------------------------------

    def peek(self, addr: int) -> int:
        """Monitor ``D``: the RAM byte at ``addr`` (00-7F)."""
        return self.mem.peek(addr)

    def poke(self, addr: int, value: int) -> int:
        """Monitor ``C``: store ``value`` at ``addr``; return what is stored there."""
        return self.mem.poke(addr, value)

    def toggle_clock(self) -> bool:
        """Monitor ``I``: toggle the clock/timer interrupt; return whether it is on.

        Turning it off freezes MVJAWS with its current latched in the DAC;
        pyrt ends a running move or jog first (current nulled, drive bit
        clear), so the jaws do not run on into a stop."""
        q = self.queue
        if q.interrupts_enabled and self.moving:
            self.drive(DAC_NULL)
            self.mem.clear_drive()
            self.move_ended("clock interrupt turned off (monitor I): move ended, current nulled")
        q.interrupts_enabled = not q.interrupts_enabled
        return q.interrupts_enabled

    @property
    def clock_enabled(self) -> bool:
        """The clock/timer interrupt is on (the ready queue runs)."""
        return self.queue.interrupts_enabled

    def led_test(self, pattern: int) -> int:
        """Monitor ``L``: store the word at 2D/2E, show it on the LEDs; return RAM 2D."""
        if not 0 <= pattern <= 0xFFFF:
            raise CommandError(f"bit pattern {pattern:X} is not a word (0000-FFFF)")
        ram = self.ram
        ram[PROX] = pattern & 0xFF
        ram[OTHER] = pattern >> 8
        self.cpu.movx_write(LED_LO, ram[PROX])
        self.cpu.movx_write(LED_HI, ram[OTHER])
        return ram[PROX]

    # -- the component contract ------------------------------------------------------

    def children(self) -> list[Component]:
        return [self.monitor]

    def signals(self) -> list[Signal]:
        """The RAM variables by their Appendix A names (words signed where
        002 treats them so) and the DAC."""
        ram = self.ram
        counts = self.counts_text
        return [
            Signal("encoder", "counts", lambda: self._sword(ENCODER_CNT), "ENCODER_CNT (4A)",
                   "d", Source.word(ram, ENCODER_CNT, signed=True), show=counts),
            Signal("target", "counts", lambda: self._sword(COMMAND_CNT), "COMMAND_CNT (4C)",
                   "d", Source.word(ram, COMMAND_CNT, signed=True), show=counts),
            Signal("error", "counts+128", lambda: self.word(ERROR_CNT),
                   "ERROR_CNT (46), excess-128", "04X", Source.word(ram, ERROR_CNT)),
            Signal("rate", "counts/check", lambda: self._sword(RATE), "RATE (48)", "d",
                   Source.word(ram, RATE, signed=True)),
            Signal("old_enc", "counts", lambda: self._sword(OLD_ENC), "OLD_ENC (4E)", "d",
                   Source.word(ram, OLD_ENC, signed=True), show=counts),
            Signal("flags", "byte", lambda: ram[FLAGS], "FLAGS (2C)", "02X",
                   Source.item(ram, FLAGS)),
            Signal("sensors", "word", lambda: self.word(PROX), "sensor word (2E:2D)", "04X",
                   Source.word(ram, PROX)),
            Signal("stopcnt", "bumps", lambda: ram[STOPCNT], "STOPCNT (50)", "d",
                   Source.item(ram, STOPCNT)),
            Signal("dac", "byte", lambda: self._dac, "drive current, excess-128", "02X",
                   Source.call(lambda: self._dac)),
            Signal("moving", "bool", lambda: self.moving, "drive or jog bit set", "d"),
            Signal("busy", "bool", lambda: self.busy, "init or calibration running", "d"),
        ]

    def counts_text(self, counts: Any) -> str:
        """A jaw position as every console view shows it: the hex word the
        letters use, the opening in mm beside it (``E47A (26.2 mm)``)."""
        c = int(counts)
        return f"{c & 0xFFFF:04X} ({self.calibration.mm(c):.1f} mm)"

    def signal(self, name: str) -> Signal | None:
        """A signal by name, or any RAM byte as ``ram:XX``."""
        key = name.lower()
        if key.startswith("ram:"):
            addr = parse_hex(key[4:], "RAM address", 0x7F)
            return Signal(f"ram:{addr:02X}", "byte", lambda: self.ram[addr],
                          f"RAM byte {addr:02X}", "02X", Source.item(self.ram, addr))
        return super().signal(name)


class GripperMove(MotionType):
    """The P move: motion gripper_move target=COUNTS (-8000..0, decimal, or hex as P takes it).

    It sets the target and the drive bit and is done when MVJAWS clears the
    drive bit (STOPCNT bumps after the stopped bit).  Its record is
    ``MotionRecord("gripper_move", {"target": counts})``; :meth:`check`
    refuses a malformed record when it is queued."""

    name = "gripper_move"

    @classmethod
    def target_of(cls, params: Any) -> int:
        """The record's target in counts, or CommandError saying what is wrong."""
        extra = sorted(set(params) - {"target"})
        if extra:
            raise CommandError(f"gripper_move: unknown parameter {extra[0][:40]!r}; "
                               "it takes target=COUNTS (-8000..0000)")
        if "target" not in params:
            raise CommandError("gripper_move: target=COUNTS missing (-8000..0000)")
        value = params["target"]
        if isinstance(value, (bool, float)):
            raise CommandError(f"gripper_move: target {str(value)[:40]!r} is not a whole "
                               "number of counts (-8000..0000)")
        if isinstance(value, int):
            if not -0x8000 <= value <= 0:
                raise CommandError(f"gripper_move: target {value} is out of range "
                                   "(-32768..0 counts, 0 wide open)")
            return value
        return parse_target(str(value))

    @classmethod
    def check(cls, robot: Any, params: Any) -> None:
        """Refuse now (CommandError) a record that could never start."""
        cls.target_of(params)
        robot.check_can_move()

    def start(self, robot: Any, record: MotionRecord, now_ns: int) -> None:
        self.robot = robot
        self.target = self.target_of(record.params)
        robot.move(self.target)  # refuses a busy or faulted robot

    def step(self, now_ns: int) -> None:
        if not self.robot.moving:
            self.stop(self.robot.last_stop or "stopped")


GripperMove.drives = (GripperController,)
register_motion_type(GripperMove.name, GripperMove, replace=True)
