"""The gripper's command records: 002's ``CMD:`` letters and its interactive monitor.

Letters, exactly as the report (Appendix C): at ``CMD:`` C E I M P S T W X
(:class:`CommandLetters`, records of the gripper controller), in the
monitor (prompt ``* ``) C D I L N Q S (:class:`GripperMonitor`, a child
component).  Numbers are hexadecimal in and out; lower case is accepted.
The grammar (:func:`parse_hex`, :func:`parse_target`) checks the words on
the console's side; every handler runs in the loop's thread.
"""

from __future__ import annotations

import re
from typing import Any

from pyrt.boards.i8031 import JSPEED, MVJAWSPD, SENSORPD, SP_RESET, SYSCLKPD, WTCHJWSPD
from pyrt.component import Arg, Component, Param, Signal, Switch, command
from pyrt.errors import CommandError
from pyrt.scheduler.motion import MotionRecord
from pyrt.units import NUMBER_PATTERN, UnitError, parse_value, units_of

__all__ = ["CommandLetters", "GripperMonitor", "parse_hex", "parse_position", "parse_target",
           "sensor_names"]

#: The sensor word's bits by name (Appendix A: 2E high byte, 2D low byte).
SENSOR_BITS = (
    (10, "limit"), (9, "overload"), (8, "crossfire"),
    (7, "right -X"), (6, "right +X"), (5, "right +Z"), (4, "right -Ya"),
    (3, "left -X"), (2, "left +X"), (1, "left +Z"), (0, "left +Ya"),
)


#: SP while the command loop runs (main called it) and inside the monitor.
SP_CMDLOOP = SP_RESET + 2
SP_MONITOR = SP_RESET + 4


def sensor_names(word: int) -> str:
    """The sensors that are ON in ``word`` (bit 0 = ON), by name."""
    on = [name for bit, name in SENSOR_BITS if not word >> bit & 1]
    return ", ".join(on) if on else "none"

_HEX = re.compile(r"[0-9A-Fa-f]+")


def parse_hex(text: str, what: str, maximum: int, minimum: int = 0) -> int:
    """A hexadecimal number ``minimum``..``maximum``; CommandError naming
    ``what`` and the range otherwise (quoting at most 40 characters)."""
    t = text.strip()
    width = 4 if maximum > 0xFF else 2
    span = f"{minimum:0{width}X}..{maximum:0{width}X}"
    if not t:
        raise CommandError(f"{what} missing (hexadecimal, {span})")
    if not _HEX.fullmatch(t):
        raise CommandError(f"{what} {t[:40]!r} is not a hexadecimal number ({span})")
    value = int(t, 16)
    if not minimum <= value <= maximum:
        raise CommandError(f"{what} {t[:40].upper()} is out of range ({span})")
    return value


#: An opening with its length unit (``42.5mm``, ``4.25cm``): the one number
#: grammar's (:func:`pyrt.units.parse_value`); without a unit a target is hex.
_OPENING = re.compile(rf"({NUMBER_PATTERN})\s*({'|'.join(units_of('length'))})",
                      re.IGNORECASE)


def parse_target(text: str) -> int:
    """A ``P`` target: 4 hex digits two's complement (``E47A``) or negative (``-1B86``).

    Returns the signed count (-8000..0000).  Positive targets are refused:
    encoder counts are never positive (0000 is wide open).
    """
    t = text.strip()
    if not t:
        raise CommandError("P needs a target, e.g. P E47A, P -1B86 or P 42.5mm")
    sign = ""
    if t[0] in "+-":
        sign, t = t[0], t[1:].strip()
    if not _HEX.fullmatch(t or "?"):
        raise CommandError(f"target {text.strip()[:40]!r} is not a hexadecimal number")
    magnitude = int(t, 16)
    if sign == "-":
        if magnitude > 0x8000:
            raise CommandError(f"target -{t[:40].upper()} is out of range (-8000..0000)")
        return -magnitude
    if magnitude > 0xFFFF:
        raise CommandError(f"target {t[:40].upper()} is more than 4 hex digits (0000..FFFF)")
    value = magnitude - 0x10000 if magnitude & 0x8000 else magnitude
    if value > 0:
        raise CommandError(
            f"target {t[:40].upper()} refused: it is positive; encoder counts run from 0000 "
            "(wide open) down to about D600 (closed): nothing moved"
        )
    return value


def parse_position(text: str, calibration: Any) -> int:
    """A ``P`` target as :func:`parse_target` takes it (hexadecimal, as 002
    writes it), or an opening with its length unit (``42.5mm``, ``4.25cm``)
    converted with the station's ``calibration``."""
    t = text.strip()
    if _OPENING.fullmatch(t) is None:
        return parse_target(t)
    try:
        mm = parse_value(t, "mm")
    except UnitError as exc:
        raise CommandError(f"target {t[:40]!r}: {exc}") from None
    if not 0.0 <= mm <= calibration.open_mm:
        raise CommandError(f"target {t[:40]} is out of range (0..{calibration.open_mm:g} mm)")
    return calibration.counts(mm)


def _hex_arg(name: str, what: str, maximum: int) -> Arg:
    return Arg(name, lambda t: parse_hex(t, what, maximum))


def _word(value: int) -> str:
    return f"{value:04X}"


def _job_reply(enter_monitor_on_failure: bool, show_closed: bool = False):
    def reply(result: Any) -> Any:
        if result is None:
            return None
        lines: list[str] = []
        if not result.ok and show_closed and result.value is not None:
            lines.append(f"closed at {result.value:04X}")
        lines.append(result.message)
        if not result.ok and enter_monitor_on_failure:
            return Switch("monitor", tuple(lines))
        return lines

    return reply


class CommandLetters:
    """The ``CMD:`` letters of 002 Appendix C, as command records of the
    gripper controller (mixed into :class:`~pyrt.robots.gripper.GripperController`)."""

    #: The station's motion queue (None: ``P`` sets the target directly, as the 8031 did).
    motion: Any = None
    monitor: GripperMonitor

    @command(name="C", moves=True, reply=_job_reply(True, show_closed=True))
    def cmd_calibrate(self) -> Any:
        """C: open fully, close fully, report the encoder count at closed, re-initialize.

        The count shown is slightly more than the true range (linkage play and
        jaw-surface compliance).  If either initialization fails, the monitor
        is entered."""
        return self.start_calibration()  # type: ignore[attr-defined]

    @command(name="E", reads_only=True, reply=_word)
    def cmd_error(self) -> int:
        """E: error between actual and target position, excess-128 (0080 = no error).

        008F: the jaws are 15 counts past the target (more open); 007A: 6 short."""
        return self.error()  # type: ignore[attr-defined]

    @command(name="I", moves=True, reply=_job_reply(True))
    def cmd_init(self) -> Any:
        """I: initialize: zero the encoder variables and drive the jaws wide open.

        If the jaws stop before the limit sensor fires, the drive current is
        nulled, an error is printed and the monitor is entered."""
        return self.start_init()  # type: ignore[attr-defined]

    @command(name="M")
    def cmd_monitor(self) -> Switch:
        """M: enter the interactive monitor (prompt "* "; Q returns)."""
        return Switch("monitor")

    @command(Arg("target", str, rest=True), name="P", moves=True)
    def cmd_position(self, text: str) -> str | None:
        """P target: move to a target encoder count (hex, two's complement or negative) or mm.

        P E47A and P-1B86 are the same move; 0000 is wide open, about D600
        closed; P 42.5mm moves to a 42.5 mm opening (the station's
        calibration).  A positive target is refused and nothing moves.  P
        returns at once; 'wait' waits for the move to end.  A P given while
        the jaws move replaces the target of that move (as 002's P does); 'stop'
        ends it.  Every move is supervised: one that does not settle within
        its bound (from the distance, the speed X and the schedule in RAM),
        oscillates about the target or stalls is a gripper fault."""
        target = parse_position(text, self.calibration)  # type: ignore[attr-defined]
        if self.motion is None or self.replaces_target():  # type: ignore[attr-defined]
            self.move(target)  # type: ignore[attr-defined]
            return None
        self.check_can_move()  # type: ignore[attr-defined]
        self.motion.put(MotionRecord("gripper_move", {"target": target}))
        return None

    @command(name="S", reads_only=True,
             reply=lambda w: [f"{w:016b}", f"on: {sensor_names(w)}"])
    def cmd_sensors(self) -> int:
        """S: the sensor word as 16 bits (2E then 2D), then the sensors that are ON by name.

        A 0 bit is a sensor that is ON.

        Bit 10 limit, 9 overload, 8 crossfire; 7..4 right jaw -X +X +Z -Ya;
        3..0 left jaw -X +X +Z +Ya; bits 15..11 unused."""
        # The bits are RAM 2E (high byte) and 2D, as Appendix A lays them out
        # (2E.0 crossfire, 2E.1 overload, 2E.2 limit; the L command's table
        # agrees).  002's S table lists bits 10..8 the other way round and puts
        # the word at "2E and 2F": both slips; 2F is the ready queue's T.
        return self.sensor_word()  # type: ignore[attr-defined]

    @command(name="T", reads_only=True, reply=_word)
    def cmd_target(self) -> int:
        """T: the target position (encoder counts)."""
        return self.target()  # type: ignore[attr-defined]

    @command(name="W", reads_only=True, reply=_word)
    def cmd_where(self) -> int:
        """W: the current position (encoder counts)."""
        return self.position()  # type: ignore[attr-defined]

    @command(Arg("speed", lambda t: parse_hex(t, "speed", 0x7F, 1)), name="X")
    def cmd_speed(self, speed: int) -> str:
        """X speed: maximum jaw speed, 01..7F (7F original gears; 33 high-ratio worm).

        Says what it changed: JSPEED (51), MXPJSPD (52) and MXNJSPD (53)."""
        return self.set_speed(speed)  # type: ignore[attr-defined]

    def params(self) -> list[Param]:
        """``speed`` (X) and the schedule bytes (monitor C 42..45), by name, with the
        checks of X and of the monitor's C (a schedule the controller cannot serve
        is refused; one predicted to oscillate is stored with the warning)."""
        ram = self.ram  # type: ignore[attr-defined]

        def byte(addr: int, name: str, units: str, doc: str) -> Param:
            def write(value: int) -> str | None:
                warning = self.schedule_warning(addr, value)  # type: ignore[attr-defined]
                self.poke(addr, value)  # type: ignore[attr-defined]
                return f"warning: {warning}" if warning else None

            return Param(name, units, lambda: ram[addr], write, 1, 0xFF,
                         f"RAM {addr:02X}: {doc}", integer=True, hex=True)

        return [
            Param("speed", "speed byte", lambda: ram[JSPEED], self.set_speed,  # type: ignore[attr-defined]
                  1, 0x7F, "X: maximum jaw speed (7F original gears; 33 high-ratio worm)",
                  integer=True, hex=True),
            byte(SYSCLKPD, "SYSCLKPD", "ticks", "ticks per ready-queue clock period"),
            byte(MVJAWSPD, "MVJAWSPD", "clock periods", "MVJAWS period"),
            byte(SENSORPD, "SENSORPD", "clock periods", "SENSORS period"),
            byte(WTCHJWSPD, "WTCHJWSPD", "clock periods", "WATCHJAW period"),
        ]

    def enter_level(self) -> list[str]:
        """Back at ``CMD:`` from the monitor; a reminder if the clock is still off."""
        self.monitor.leave()
        if not self.clock_enabled:  # type: ignore[attr-defined]
            return ["note: the clock interrupt is still OFF (ready queue frozen); M then I: on"]
        return []


def _show(pair: tuple[int, int]) -> str:
    return f"{pair[0]:02X} {pair[1]:02X}"


class GripperMonitor(Component):
    """The interactive monitor of 002 (prompt ``* ``) over the controller's RAM."""

    name = "monitor"

    def __init__(self, controller: Any):
        self.ctl = controller
        #: The monitor's current address (the last one C, D, L or N showed).
        self.address = 0

    def signals(self) -> list[Signal]:
        return [Signal.attr("address", "address", self, "address", "the monitor's address",
                            fmt="02X")]

    def enter_level(self) -> list[str]:
        """Entered from ``CMD:`` (the command loop calls the monitor): the
        address starts at SP, the monitor's first address, as 002 says."""
        cpu = self.ctl.cpu
        cpu.sp = SP_MONITOR
        self.address = cpu.sp
        return []

    def leave(self) -> None:
        """The monitor returns to the command loop."""
        self.ctl.cpu.sp = SP_CMDLOOP

    def _at(self, addr: int, value: int) -> tuple[int, int]:
        self.address = addr
        return addr, value

    @command(_hex_arg("addr", "address", 0x7F), _hex_arg("value", "value", 0xFF), name="C",
             moves=True)
    def cmd_change(self, addr: int, value: int) -> list[str]:
        """C addr value: store value (00-FF) at on-chip RAM addr (00-7F), show it.

        A schedule variable (42 SYSCLKPD, 43 MVJAWSPD, 44 SENSORPD, 45
        WTCHJWSPD) the controller cannot serve is refused with the reason;
        one the supervision predicts will make moves oscillate is stored
        with a warning."""
        warning = self.ctl.schedule_warning(addr, value)
        lines = [_show(self._at(addr, self.ctl.poke(addr, value)))]
        if warning:
            lines.append(f"warning: {warning}")
        return lines

    @command(_hex_arg("addr", "address", 0x7F), name="D", reads_only=True, reply=_show)
    def cmd_display(self, addr: int) -> tuple[int, int]:
        """D addr: show the on-chip RAM byte at addr (00-7F)."""
        return self._at(addr, self.ctl.peek(addr))

    @command(name="I")
    def cmd_interrupt(self) -> str:
        """I: toggle the clock/timer interrupt (off: ready queue frozen, sensors not read).

        A move running when it goes off is ended first (current nulled)."""
        was_moving = self.ctl.moving
        if self.ctl.toggle_clock():
            return "clock interrupt ON"
        if was_moving:
            return "clock interrupt OFF (ready queue frozen); the move was ended, current nulled"
        return "clock interrupt OFF (ready queue frozen)"

    @command(_hex_arg("pattern", "bit pattern", 0xFFFF), name="L", reply=_show)
    def cmd_leds(self, pattern: int) -> tuple[int, int]:
        """L pattern: store the word at 2D (low byte) and 2E, light the LEDs, show 2D.

        An LED is on iff its bit is 0 (0000 all on, FFFF all off).  Turn the
        clock interrupt off first (I), or SENSORS overwrites the pattern."""
        return self._at(0x2D, self.ctl.led_test(pattern))

    @command(name="N", reads_only=True, reply=_show)
    def cmd_next(self) -> tuple[int, int]:
        """N: show the next on-chip RAM address (after the last C, D, L or N) and its contents."""
        addr = (self.address + 1) & 0x7F  # past 7F the 8031 has no RAM: wrap to 00
        return self._at(addr, self.ctl.peek(addr))

    @command(name="Q")
    def cmd_quit(self) -> Switch:
        """Q: quit the monitor, back to CMD:."""
        return Switch("gripper")

    @command(name="S", reads_only=True, reply=lambda sp: f"SP {sp:02X}")
    def cmd_stack(self) -> int:
        """S: show the stack pointer SP (SFR 81; D cannot reach it)."""
        return self.ctl.cpu.sp
