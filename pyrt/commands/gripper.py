"""The gripper's command interpreters: 002's ``CMD:`` level and interactive monitor.

Letters, exactly as the report (Appendix C): at ``CMD:`` C E I M P S T W X,
in the monitor (prompt ``* ``) C D I L N Q S.  Numbers are hexadecimal in
and out, lower case is accepted, and the argument may follow the letter with
or without a space (``P-1B86``, ``P E47A``).  Beyond the report, as whole
words so they never collide with the letters: ``help``, ``wait``, ``sleep``,
``stats``, ``sim`` and ``quit``.

The interpreter never touches the RAM or the devices itself: every read and
every change is a function run in the loop's thread through the runner's
mailbox (``runner.call``), and waits are ``runner.wait_until``.  A bad
command prints one line and changes nothing.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol, TextIO

from pyrt.commands._motion import motion_type_lines, parse_motion
from pyrt.commands.scope import ScopeCommand
from pyrt.commands.shell import CommandShell, parse_number, parse_seconds
from pyrt.errors import CommandError, FaultError, PyrtError
from pyrt.robots.gripper import GripperMove
from pyrt.scheduler.motion import MotionExecutor, MotionRecord
from pyrt.scheduler.report import format_statistics
from pyrt.scope import Scope, Source

if TYPE_CHECKING:
    from pyrt.robots.gripper import GripperController
    from pyrt.sim.gripper import JawPlant

__all__ = ["GripperShell", "gripper_channels", "parse_hex", "parse_target"]

#: Loop-time limits of the blocking commands, seconds.
INIT_TIMEOUT_S = 120.0
CAL_TIMEOUT_S = 240.0
WAIT_TIMEOUT_S = 120.0

_HEX = re.compile(r"[0-9A-Fa-f]+")
_MIN_COUNT = -0x8000


class Runner(Protocol):
    """What the interpreter needs of :class:`pyrt.scheduler.runner.Runner`."""

    loop: Any

    def call(self, fn: Callable[..., Any], *args: Any, timeout_s: float = 1.0) -> Any: ...

    def wait_until(self, predicate: Callable[[], bool], timeout_s: float) -> bool: ...

    def sleep(self, seconds: float) -> None: ...


def parse_hex(text: str, what: str, maximum: int) -> int:
    """A hexadecimal number 0..``maximum``; CommandError naming ``what`` otherwise."""
    t = text.strip()
    if not t:
        raise CommandError(f"{what} missing (hexadecimal)")
    if not _HEX.fullmatch(t):
        raise CommandError(f"{what} {t!r} is not a hexadecimal number")
    value = int(t, 16)
    if value > maximum:
        raise CommandError(f"{what} {t.upper()} is out of range (00..{maximum:X})")
    return value


def parse_target(text: str) -> int:
    """A ``P`` target: 4 hex digits two's complement (``E47A``) or negative (``-1B86``).

    Returns the signed count (-8000..0000).  Positive targets are refused:
    encoder counts are never positive (0000 is wide open).
    """
    t = text.strip()
    if not t:
        raise CommandError("P needs a target, e.g. P E47A or P -1B86")
    sign = ""
    if t[0] in "+-":
        sign, t = t[0], t[1:].strip()
    if not _HEX.fullmatch(t or "?"):
        raise CommandError(f"target {text.strip()!r} is not a hexadecimal number")
    magnitude = int(t, 16)
    if sign == "-":
        if magnitude > 0x8000:
            raise CommandError(f"target -{t.upper()} is out of range (-8000..0000)")
        return -magnitude
    if magnitude > 0xFFFF:
        raise CommandError(f"target {t.upper()} is more than 4 hex digits (0000..FFFF)")
    value = magnitude - 0x10000 if magnitude & 0x8000 else magnitude
    if value > 0:
        raise CommandError(
            f"target {t.upper()} refused: it is positive; encoder counts run from 0000 "
            "(wide open) down to about D600 (closed): nothing moved"
        )
    return value


def gripper_channels(
    controller: GripperController, plant: JawPlant | None = None
) -> dict[str, Source]:
    """The scope channels of the gripper: RAM variables by their Appendix A
    names (words signed where 002 treats them so), the DAC, and the
    simulated jaws when there is a plant.  Any RAM byte is ``ram:XX``."""
    ram = controller.ram
    channels = {
        "encoder": Source.word(ram, 0x4A, signed=True),
        "target": Source.word(ram, 0x4C, signed=True),
        "error": Source.word(ram, 0x46),
        "rate": Source.word(ram, 0x48, signed=True),
        "old_enc": Source.word(ram, 0x4E, signed=True),
        "flags": Source.item(ram, 0x2C),
        "sensors": Source.word(ram, 0x2D),
        "stopcnt": Source.item(ram, 0x50),
        "dac": Source.call(lambda: controller.dac),
    }
    if plant is not None:
        channels.update(
            {
                "jaws.x": Source.attr(plant, "x"),
                "jaws.v": Source.attr(plant, "v"),
                "jaws.squeeze": Source.attr(plant, "squeeze"),
                "jaws.dac": Source.attr(plant.board, "dac"),
            }
        )
    return channels


def _signed(word: int) -> int:
    return word - 0x10000 if word & 0x8000 else word


class _Level:
    """A command level: its letters are its ``do_<letter>`` methods."""

    prompt = ""

    def __init__(self, shell: GripperShell):
        self.shell = shell
        self.say = shell.say
        self.ctl = shell.ctl
        self.runner = shell.runner

    def call(self, fn: Callable[..., Any], *args: Any) -> Any:
        return self.runner.call(fn, *args)

    @staticmethod
    def no_argument(letter: str, arg: str) -> None:
        if arg:
            raise CommandError(f"{letter} takes no argument (got {arg!r})")


class CommandLevel(_Level):
    """The top level, prompt ``CMD: `` (002 Appendix C)."""

    prompt = "CMD: "

    def do_c(self, arg: str) -> None:
        """C: open fully, close fully, report the encoder count at closed, re-initialize.

        The count shown is slightly more than the true range (linkage play and
        jaw-surface compliance).  If either initialization fails, the monitor
        is entered."""
        self.no_argument("C", arg)
        result = self.shell.run_job(self.ctl.start_calibration, CAL_TIMEOUT_S)
        if result is None:
            return
        if result.ok:
            self.say(result.message)
        else:
            if result.value is not None:
                self.say(f"closed at {result.value:04X}")
            self.say(result.message)
            self.shell.enter_monitor()

    def do_e(self, arg: str) -> None:
        """E: error between actual and target position, excess-128 (0080 = no error).

        008F: the jaws are 15 counts past the target (more open); 007A: 6 short."""
        self.no_argument("E", arg)
        self.say(f"{self.call(self.ctl.error):04X}")

    def do_i(self, arg: str) -> None:
        """I: initialize: zero the encoder variables and drive the jaws wide open.

        If the jaws stop before the limit sensor fires, the drive current is
        nulled, an error is printed and the monitor is entered."""
        self.no_argument("I", arg)
        self.shell.initialize()

    def do_m(self, arg: str) -> None:
        """M: enter the interactive monitor (prompt "* "; Q returns)."""
        self.no_argument("M", arg)
        self.shell.enter_monitor()

    def do_p(self, arg: str) -> None:
        """P target: move to a target encoder count (hex, two's complement or negative).

        P E47A and P-1B86 are the same move; 0000 is wide open, about D600
        closed.  A positive target is refused and nothing moves.  P returns
        at once; 'wait' waits for the move to end.  Moves go on the motion
        queue: a P given while the jaws move runs when that move has ended."""
        target = parse_target(arg)
        executor = self.shell.executor
        if executor is None:
            self.call(self.ctl.move, target)
            return
        self.call(self.ctl.check_can_move)
        self.shell.runner.submit_motion(MotionRecord(GripperMove.name, {"target": target}))

    def do_s(self, arg: str) -> None:
        """S: the sensor word as 16 bits (2E then 2D); a 0 is a sensor that is ON.

        Bit 10 limit, 9 overload, 8 crossfire; 7..4 right jaw -X +X +Z -Ya;
        3..0 left jaw -X +X +Z +Ya; bits 15..11 unused."""
        # The bits are RAM 2E (high byte) and 2D, as Appendix A lays them out
        # (2E.0 crossfire, 2E.1 overload, 2E.2 limit; the L command's table
        # agrees).  002's S table lists bits 10..8 the other way round and puts
        # the word at "2E and 2F": both slips; 2F is the ready queue's T.
        self.no_argument("S", arg)
        self.say(f"{self.call(self.ctl.sensor_word):016b}")

    def do_t(self, arg: str) -> None:
        """T: the target position (encoder counts)."""
        self.no_argument("T", arg)
        self.say(f"{self.call(self.ctl.target):04X}")

    def do_w(self, arg: str) -> None:
        """W: the current position (encoder counts)."""
        self.no_argument("W", arg)
        self.say(f"{self.call(self.ctl.position):04X}")

    def do_x(self, arg: str) -> None:
        """X speed: maximum jaw speed, 01..7F (7F original gears; 33 high-ratio worm)."""
        speed = parse_hex(arg, "speed", 0xFF)
        self.call(self.ctl.set_speed, speed)


class MonitorLevel(_Level):
    """The interactive monitor, prompt ``* `` (002 Appendix C)."""

    prompt = "* "

    def _show(self, addr: int, value: int) -> None:
        self.shell.address = addr
        self.say(f"{addr:02X} {value:02X}")

    def do_c(self, arg: str) -> None:
        """C addr value: store value (00-FF) at on-chip RAM addr (00-7F), show it."""
        parts = arg.split()
        if len(parts) != 2:
            raise CommandError("C needs an address and a value: C addr value (hex)")
        addr = parse_hex(parts[0], "address", 0x7F)
        value = parse_hex(parts[1], "value", 0xFF)
        self._show(addr, self.call(self.ctl.poke, addr, value))

    def do_d(self, arg: str) -> None:
        """D addr: show the on-chip RAM byte at addr (00-7F)."""
        parts = arg.split()
        if len(parts) != 1:
            raise CommandError("D needs one address: D addr (hex 00-7F)")
        addr = parse_hex(parts[0], "address", 0x7F)
        self._show(addr, self.call(self.ctl.peek, addr))

    def do_i(self, arg: str) -> None:
        """I: toggle the clock/timer interrupt (off: ready queue frozen, sensors not read)."""
        self.no_argument("I", arg)
        on = self.call(self.ctl.toggle_clock)
        self.say("clock interrupt ON" if on else "clock interrupt OFF (ready queue frozen)")

    def do_l(self, arg: str) -> None:
        """L pattern: store the word at 2D (low byte) and 2E, light the LEDs, show 2D.

        An LED is on iff its bit is 0 (0000 all on, FFFF all off).  Turn the
        clock interrupt off first (I), or SENSORS overwrites the pattern."""
        parts = arg.split()
        if len(parts) != 1:
            raise CommandError("L needs one bit pattern: L pattern (hex 0000-FFFF)")
        pattern = parse_hex(parts[0], "bit pattern", 0xFFFF)
        self._show(0x2D, self.call(self.ctl.led_test, pattern))

    def do_n(self, arg: str) -> None:
        """N: show the next on-chip RAM address (after the last C, D, L or N) and its contents."""
        self.no_argument("N", arg)
        addr = (self.shell.address + 1) & 0x7F  # past 7F the 8031 has no RAM: wrap to 00
        self._show(addr, self.call(self.ctl.peek, addr))

    def do_q(self, arg: str) -> None:
        """Q: quit the monitor, back to CMD:."""
        self.no_argument("Q", arg)
        self.shell.leave_monitor()

    def do_s(self, arg: str) -> None:
        """S: show the stack pointer SP (SFR 81; D cannot reach it)."""
        self.no_argument("S", arg)
        self.say(f"SP {self.call(self.ctl.stack_pointer):02X}")


class GripperShell(CommandShell):
    """The gripper's interpreter: the two letter levels plus the pyrt words.

    ``runner`` is a :class:`~pyrt.scheduler.runner.Runner` of the loop that
    runs ``controller`` (a :class:`~pyrt.robots.gripper.GripperController`);
    ``plant`` is the simulated mechanism for the ``sim`` word (None on real
    hardware).
    """

    def __init__(
        self,
        runner: Runner,
        controller: GripperController,
        stdout: TextIO,
        plant: JawPlant | None = None,
        scope: Scope | None = None,
        executor: MotionExecutor | None = None,
    ):
        super().__init__(stdout)
        self.runner = runner
        self.ctl = controller
        self.plant = plant
        #: Runs queued P moves (None: P sets the target directly, as the 8031 did).
        self.executor = executor
        self.channels = gripper_channels(controller, plant)
        self._scope = (
            ScopeCommand(runner, scope, self._channel, lambda: sorted(self.channels), stdout)
            if scope is not None
            else None
        )
        self.top = CommandLevel(self)
        self.monitor = MonitorLevel(self)
        self.level: _Level = self.top
        #: The monitor's current address (the last one C, D, L or N showed).
        self.address = 0

    @property
    def prompt(self) -> str:  # type: ignore[override]
        return self.level.prompt

    @property
    def in_monitor(self) -> bool:
        """The monitor (prompt ``* ``) is active."""
        return self.level is self.monitor

    # -- dispatch -----------------------------------------------------------------

    def onecmd(self, line: str) -> bool:
        """Run one line; True when the session should end (``quit``)."""
        return self.guarded(self._dispatch, line)

    def _dispatch(self, line: str) -> bool:
        line = line.strip()
        if not line:
            return False
        parts = line.split(None, 1)
        word, rest = parts[0], parts[1] if len(parts) > 1 else ""
        fn = self.handler(word) if len(word) > 1 else None
        if fn is not None:
            return bool(fn(rest.strip()))
        letter = line[0]
        level_fn = self.handler(letter, self.level) if letter.isalpha() else None
        if level_fn is None:
            self._unknown(line)
            return False
        level_fn(line[1:].strip())
        return False

    def _unknown(self, line: str) -> None:
        letters = " ".join(name.upper() for name, _ in self.commands(self.level))
        where = "monitor command" if self.in_monitor else "command"
        self.error(f"unknown {where} {line.split()[0]!r} (letters: {letters}; words: type help)")

    def fault(self, exc: FaultError) -> None:
        self.say(f"FAULT: {exc.fault.cause} (in {exc.fault.source or 'the controller'})")
        for _ in range(8):  # each pending fault is raised once: show them all
            try:
                self.runner.poll()
            except FaultError as again:
                self.say(f"FAULT: {again.fault.cause} (in {again.fault.source})")
                continue
            except PyrtError:
                pass
            break
        self.say("the command was not run; drive current is off and the jaws refuse to move "
                 "until you type ack")

    # -- blocking main-program sequences ------------------------------------------

    def run_job(self, start: Callable[[], Any], timeout_s: float) -> Any:
        """Start a foreground job (init, calibration) and wait for its result."""
        job = self.runner.call(start)
        if not self.runner.wait_until(lambda: job.done, timeout_s):
            self.runner.call(job.cancel)
            self.error(f"{job.name} did not finish within {timeout_s:g} s; stopped")
            return None
        if job.error is not None:
            raise job.error
        if job.result is None:
            self.error(f"{job.name} was abandoned (fault)")
        return job.result

    def initialize(self) -> bool:
        """``I``: init and fullopen; on failure print why and enter the monitor."""
        result = self.run_job(self.ctl.start_init, INIT_TIMEOUT_S)
        if result is None:
            return False
        self.say(result.message)
        if not result.ok:
            self.enter_monitor()
        return bool(result.ok)

    def enter_monitor(self) -> None:
        """Switch to the monitor; its address starts at SP, as 002 says."""
        self.address = self.runner.call(self.ctl.enter_monitor)
        self.level = self.monitor

    def leave_monitor(self) -> None:
        """Back to ``CMD:``; remind the user if the clock interrupt is still off."""
        self.runner.call(self.ctl.leave_monitor)
        self.level = self.top
        if not self.runner.call(lambda: self.ctl.clock_enabled):
            self.say("note: the clock interrupt is still OFF (ready queue frozen); M then I: on")

    # -- the words ----------------------------------------------------------------

    def do_help(self, arg: str) -> None:
        """help [command]: list the commands of this level, or explain one."""
        topic = arg.strip()
        if topic:
            owner = self.level if len(topic) == 1 else None
            text = self.help_text(topic, owner)
            if text is None:
                self.error(f"no help for {topic!r}")
            else:
                self.say(text)
            return
        title = "monitor commands (prompt *)" if self.in_monitor else "commands (prompt CMD:)"
        self.say(title + ":")
        for name, line in self.commands(self.level):
            same = line[:1].upper() == name.upper()
            self.say(f"  {line}" if same else f"  {name.upper()}  {line}")
        self.say("words:")
        for _name, line in self.commands():
            self.say(f"  {line}")
        self.say("numbers are hexadecimal; lower case is accepted; 'help X' explains X")

    def do_wait(self, arg: str) -> None:
        """wait [SECONDS]: wait until the current move, jog or init ends; say why it ended."""
        timeout = WAIT_TIMEOUT_S
        if arg.strip():
            timeout = parse_seconds(arg, "wait")
        ctl = self.ctl
        executor, motion = self.executor, self.runner.motion

        def active() -> bool:
            queued = executor is not None and (executor.busy or len(motion) > 0)
            return ctl.moving or ctl.busy or queued

        busy, clock = self.runner.call(lambda: (active(), ctl.clock_enabled))
        if not busy:
            self.say("nothing to wait for: jaws idle")
            return
        if not clock:
            self.say("the clock interrupt is OFF (monitor I): the move cannot end; M, I: on")
            return
        if not self.runner.wait_until(lambda: not active(), timeout):
            self.say(f"still moving after {timeout:g} s")
            return
        why, pos, tgt = self.runner.call(lambda: (ctl.last_stop, ctl.position(), ctl.target()))
        err = _signed(pos) - _signed(tgt)
        self.say(f"{why or 'ended'}: position {pos:04X}, target {tgt:04X}, error {err:+d}")

    def do_ack(self, arg: str) -> None:
        """ack: acknowledge a fault: the routines restart, the jaws may move again."""
        if arg.strip():
            raise CommandError("ack takes no argument")
        fault = self.runner.call(lambda: self.ctl.queue.fault)
        if fault is None:
            self.say("no fault to acknowledge")
            return
        self.runner.call(self.ctl.acknowledge)
        self.say(f"fault acknowledged ({fault.cause}); routines restarted, nothing moved")

    def do_sleep(self, arg: str) -> None:
        """sleep SECONDS: let the controller run that long (loop time)."""
        self.runner.sleep(parse_seconds(arg, "sleep"))

    def do_stats(self, arg: str) -> None:
        """stats: per-task timing of the loop (calls, mean, p99, max, overruns)."""
        self.say(format_statistics(self.runner.statistics()))

    def do_sim(self, arg: str) -> None:
        """sim [object MM|none] [jog open|close|off [S]] [fault NAME|none]: the simulation.

        With no argument, the simulated world's state.  'object' puts an
        object MM wide between the jaws; 'jog' holds the front-panel jog
        switch; 'fault' injects limit (sensor dead), jam (motor), encoder
        (dead), port 2D|2E XX (sensor port stuck at XX), or none (clear)."""
        plant = self.plant
        if plant is None:
            raise CommandError("no simulated gripper (sim works on the simulation only)")
        parts = arg.lower().split()
        if not parts:
            status, leds = self.runner.call(lambda: (plant.status(), plant.board.leds))
            self.say(f"{status}; LEDs {leds:04X}")
            return
        what, rest = parts[0], parts[1:]
        if what == "object":
            if len(rest) != 1:
                raise CommandError("sim object MM (width in mm) or sim object none")
            width = None if rest[0] == "none" else parse_number(rest[0], "object width")
            self._sim(plant.set_object, width)
        elif what == "jog":
            if not rest or rest[0] not in ("open", "close", "off") or len(rest) > 2:
                raise CommandError("sim jog open|close|off [SECONDS]")
            dur = None
            if len(rest) == 2:
                dur = int(parse_seconds(rest[1], "jog") * 1e9)
            self._sim(plant.jog, rest[0], dur)
        elif what == "fault":
            if rest == ["none"]:
                self._sim(plant.clear_faults)
            elif len(rest) == 3 and rest[0] == "port":
                value = parse_hex(rest[2], "stuck port value", 0xFF)
                self._sim(plant.inject, "port", value, rest[1].upper())
            elif len(rest) == 1 and rest[0] in ("limit", "jam", "encoder"):
                self._sim(plant.inject, rest[0])
            else:
                raise CommandError("sim fault limit|jam|encoder|none, or sim fault port 2D|2E XX")
        else:
            raise CommandError(f"unknown sim setting {what!r}: object, jog or fault")

    def _sim(self, fn: Callable[..., Any], *args: Any) -> None:
        def apply() -> None:
            try:
                fn(*args)
            except ValueError as exc:
                raise CommandError(str(exc)) from None

        self.runner.call(apply)

    def do_scope(self, arg: str) -> None:
        """scope [add CH.. | trigger CH LEVEL | run | single | stop | show | save F | plot F]

        The software oscilloscope over the gripper's variables: encoder,
        target, error, rate, flags, sensors, stopcnt, dac, jaws.x, jaws.v,
        jaws.squeeze, or any RAM byte as ram:XX.  'scope' alone: its state."""
        if self._scope is None:
            raise CommandError("no scope on this console")
        self._scope.stdout = self.stdout
        self._scope(arg)

    def _channel(self, name: str) -> Source:
        key = name.lower()
        if key in self.channels:
            return self.channels[key]
        if key.startswith("ram:"):
            addr = parse_hex(key[4:], "RAM address", 0x7F)
            return Source.item(self.ctl.ram, addr)
        raise CommandError(f"no channel {name!r}; scope list shows them")

    def do_motion(self, arg: str) -> None:
        """motion [TYPE key=value ...]: queue a motion of any registered type; alone: list them.

        motion gripper_move target=-6022 is 'P -1786' (values are decimal
        numbers where they parse as numbers)."""
        record = parse_motion(arg)
        if record is None:
            self.say("motion types (motion TYPE key=value ...):")
            for line in motion_type_lines():
                self.say(line)
            return
        if self.executor is None:
            raise CommandError("motion: this console runs no motion queue")
        self.runner.call(self.ctl.check_can_move)
        n = self.runner.submit_motion(record)  # type: ignore[attr-defined]
        self.say(f"motion {record.type} queued ({n} waiting)")

    def do_quit(self, arg: str) -> bool:
        """quit: null the drive current and leave."""
        return True
