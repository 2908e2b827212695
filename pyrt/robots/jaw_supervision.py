"""pyrt's supervision of the gripper's jaw drive, independent of the RAM.

002's fix keeps drive current from being left on jaws that do not move;
pyrt supervises every commanded move besides, whatever the monitor has
stored in RAM: a settle bound from the distance, the speed limit and the
schedule (:meth:`JawSupervision.settle_bound_ns`), oscillation about the
target seen as sign changes of the error without decay (MVJAWS feeds the
:class:`~pyrt.tasks.jawmove.MoveSupervisor`), and a stall watchdog that
trips when current has been applied longer than the stall bound
(:meth:`JawSupervision.stall_bound_ns`, at most the stall limit) without
one encoder count.

The schedule values in RAM are 002's to tune: a value the controller cannot
serve is refused (WATCHJAW faster than two encoder counts at the speed
limit, or 00), and one the supervision predicts will make moves oscillate
is stored with a warning (:meth:`JawSupervision.oscillation_reason`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from pyrt.boards.gripper import DAC_NULL
from pyrt.boards.i8031 import COMMAND_CNT, ENCODER_CNT, ERROR_CNT, JSPEED, SYSCLKPD, WTCHJWSPD
from pyrt.errors import CommandError
from pyrt.robots.gripper_ram import SCHEDULE_NAMES, GripperRam, Schedule
from pyrt.tasks.jawmove import BAND, STOPBUMPS, MoveSupervisor

if TYPE_CHECKING:
    from pyrt.robots.gripper import GripperController

__all__ = ["OSCILLATION_GAIN", "JawSupervision"]

#: MVJAWS drives with the error; with g = (counts/s per current unit) x the
#: time a current rests on one error value (MVJAWS's period plus the error's
#: age, up to WATCHJAW's), the sampled loop overshoots once g passes about 2
#: (the simulated jaws: 1.04 at 002's defaults settles; 2.2 with WTCHJWSPD
#: 10 and 3.9 with MVJAWSPD 30 oscillate; between, the deadband may or may
#: not catch the jaws: a prediction, and the supervision is the guard).
OSCILLATION_GAIN = 2.0
#: Settle bound: travel at the speed limit times this, plus the end of the move.
TRAVEL_MARGIN = 1.5
SETTLE_EXTRA_NS = 500_000_000
#: A move may hold current on jaws that do not move for STOPBUMPS MVJAWS runs
#: after WATCHJAW sees them stopped; the stall bound adds this margin.
STALL_EXTRA_NS = 100_000_000
#: The stall watchdog looks at the schedule only after this long without a count.
STALL_FLOOR_NS = 50_000_000


class _NoClock:
    """The supervision's clock before the controller is attached to a loop."""

    now_ns = 0


class JawSupervision:
    """The supervision of one controller's moves (see the module text); its
    faults are the controller's (:meth:`~pyrt.component.Component.fail`)."""

    def __init__(self, ctl: GripperController, mem: GripperRam, stall_limit_ns: int):
        self._ctl = ctl
        self._mem = mem
        self.stall_limit_ns = int(stall_limit_ns)
        #: The running move's supervision (armed by :meth:`arm`).
        self.supervisor = MoveSupervisor(_NoClock(), self._oscillating, self._not_settled)
        #: The settle bound of the running move, seconds (for its fault message).
        self.settle_bound_s = 0.0
        self._wd_pulses = 0
        self._wd_since = 0

    # -- the schedule --------------------------------------------------------------

    def schedule_refusal(self, addr: int, value: int) -> str | None:
        """Why storing ``value`` at schedule variable ``addr`` cannot be served, or None.

        WATCHJAW must see the jaws move: a period shorter than the time of
        two encoder counts at full speed (X 7F, what I drives at) leaves the
        stopped bit on while they move (an I fails; a move ends where it
        stands)."""
        if addr not in SCHEDULE_NAMES:
            return None
        if value == 0:
            return (f"{SCHEDULE_NAMES[addr]} 00 would stop the routine's clock "
                    "(schedule values are 01..FF)")
        if addr not in (SYSCLKPD, WTCHJWSPD):
            return None
        sched = self._mem.schedule().with_value(addr, value)
        need = 2e9 / self._ctl.calibration.speed(0x7F)
        if sched.watch_ns < need:
            return (f"{SCHEDULE_NAMES[addr]} {value:02X} would run WATCHJAW every "
                    f"{sched.watch_ns / 1e3:g} µs, less than two encoder counts at full speed "
                    f"({need / 1e3:.0f} µs at X 7F): the stopped bit would be on while the "
                    "jaws move")
        return None

    def oscillation_reason(self, sched: Schedule | None = None) -> str | None:
        """Why the supervision predicts that moves will oscillate on the
        schedule ``sched`` (default: the RAM's now), or None."""
        sched = sched if sched is not None else self._mem.schedule()
        gain = self._ctl.calibration.gain
        held = sched.move_ns + sched.watch_ns
        if gain * held / 1e9 <= OSCILLATION_GAIN:
            return None
        if sched.watch_ns > sched.move_ns:
            rel = "≫" if sched.watch_ns >= 2 * sched.move_ns else ">"
            return (f"WTCHJWSPD {sched.wtchjwspd:02X} {rel} MVJAWSPD {sched.mvjawspd:02X}: "
                    f"MVJAWS drives {sched.move_ns / 1e6:g} ms at a time with an error up to "
                    f"{sched.watch_ns / 1e6:g} ms old")
        return (f"MVJAWS drives {sched.move_ns / 1e6:g} ms at a time (SYSCLKPD "
                f"{sched.sysclkpd:02X} x MVJAWSPD {sched.mvjawspd:02X} x "
                f"{sched.tick_ns / 1e3:g} µs tick): too long for jaws that move "
                f"{gain:g} counts/s per current unit")

    def schedule_warning(self, addr: int, value: int) -> str | None:
        """Monitor ``C``: CommandError if ``value`` at schedule variable
        ``addr`` cannot be served; the predicted oscillation, if any, else None."""
        refusal = self.schedule_refusal(addr, value)
        if refusal:
            raise CommandError(f"C {addr:02X} {value:02X} refused: {refusal}; nothing changed")
        if addr not in SCHEDULE_NAMES:
            return None
        why = self.oscillation_reason(self._mem.schedule().with_value(addr, value))
        if why is None:
            return None
        return f"moves may oscillate: {why}; the supervision stops a move that does"

    # -- the bounds ----------------------------------------------------------------

    def settle_bound_ns(self, distance: int) -> int:
        """How long a move of ``distance`` counts may take to end, on the
        schedule and the speed limit in RAM now."""
        sched = self._mem.schedule()
        v = self._ctl.calibration.speed(self._mem.ram[JSPEED])
        travel = abs(distance) / v * TRAVEL_MARGIN * 1e9
        return int(travel + (STOPBUMPS + 4) * sched.move_ns + 4 * sched.watch_ns
                   + SETTLE_EXTRA_NS)

    def stall_bound_ns(self) -> int:
        """How long current may be held on jaws that do not move, on the
        schedule in RAM now (STOPCNT's bumps after WATCHJAW sees them stop),
        never more than :attr:`stall_limit_ns`."""
        sched = self._mem.schedule()
        bound = ((STOPBUMPS + 2) * sched.move_ns + 3 * sched.watch_ns + 3 * sched.check_ns
                 + STALL_EXTRA_NS)
        return min(bound, self.stall_limit_ns)

    # -- a move --------------------------------------------------------------------

    def arm(self, now_ns: int, distance: int) -> None:
        """A move of ``distance`` counts starts at ``now_ns``: supervise it."""
        bound = self.settle_bound_ns(distance)
        self.settle_bound_s = bound / 1e9
        self.supervisor.arm(now_ns + bound)

    def ended(self, why: str) -> str:
        """A move ended for ``why``: stop supervising it; return why, where a
        move that STOPCNT ended away from its target says that the stopped
        bit ended it, and why the schedule may have made the bit lie."""
        if why == "stopped":
            mem = self._mem
            err = mem.sword(ENCODER_CNT) - mem.sword(COMMAND_CNT)
            if abs(err) > BAND:
                sched = mem.schedule()
                why = "the stopped bit ended the move (STOPCNT ran out)"
                if sched.watch_ns >= 2 * sched.move_ns:
                    why += (f"; WTCHJWSPD {sched.wtchjwspd:02X} ≫ MVJAWSPD "
                            f"{sched.mvjawspd:02X}: the bit is up to "
                            f"{sched.watch_ns / 1e6:g} ms old")
        self.supervisor.disarm()
        return why

    def _reason(self) -> str:
        return self.oscillation_reason() or f"schedule {self._mem.schedule().text()}"

    def _oscillating(self, amplitude: int, flips: int) -> None:
        self._ctl.fail(f"P move oscillating about the target: error ±{amplitude} counts, "
                       f"{flips} sign changes without decay; {self._reason()}", source="P move")

    def _not_settled(self, error: int, amplitude: int, flips: int) -> None:
        what = (f"error oscillating ±{amplitude} counts" if flips >= 2
                else f"error {error:+d} counts")
        self._ctl.fail(f"P move did not settle within {self.settle_bound_s:.1f} s: {what}; "
                       f"{self._reason()}", source="P move")

    # -- the watchdog --------------------------------------------------------------

    def watchdog(self, now_ns: int, dac: int, pulses: int) -> None:
        """Every tick (``dac`` the drive byte, ``pulses`` the encoder
        interrupts so far): trip the robot when current has been applied
        longer than the stall bound without a single encoder count, or when
        a supervised move has outlived its settle bound (whatever the
        schedule: MVJAWS may run seldom, or not at all)."""
        sup = self.supervisor
        if sup.active and now_ns > sup.deadline_ns:
            sup.expired(self._mem.sword(ERROR_CNT) - 0x80)
            return
        if dac == DAC_NULL or pulses != self._wd_pulses:
            self._wd_pulses = pulses
            self._wd_since = now_ns
            return
        held = now_ns - self._wd_since
        if held > STALL_FLOOR_NS and held > self.stall_bound_ns():
            self._wd_since = now_ns
            sched = self._mem.schedule()
            self._ctl.fail(
                f"drive current {dac - 0x80:+d} applied for {held / 1e9:.2f} s without "
                f"jaw movement (stall bound {self.stall_bound_ns() / 1e9:.2f} s; MVJAWS every "
                f"{sched.move_ns / 1e6:g} ms)",
                source="stall watchdog",
            )
