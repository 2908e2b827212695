"""The manipulator's command interpreter: commands addressed to named objects (000, section 4).

As the document's ``Hardware::doCommand``: the first word names an object,
the rest is that object's command and arguments, names case-insensitive::

    prototype to 0 0 50          (PolyAxis, Table 2)
    axis1 up 5                   (Axis, Table 4)
    axis0Motor maxspeed 3        (Motor, section 8)
    axis0Encoder read            (Encoder, Table 8)
    axis0Loadcell calibrate      (Loadcell, section 10)

Top-level words (section 18 and pyrt's): ``quit`` (stop every motor, then
exit), ``log [FILE]`` (toggle the state log), ``debug``, ``help [object]``,
``wait``, ``sleep``, ``stats``, ``status``, ``sim``, ``ack``, and ``motion
TYPE [key=value ...]`` (any registered motion type, built-in or plug-in,
queued as ``to`` is; ``motion`` alone lists them).

Everything that reads or changes the robot runs in the loop's thread through
the runner's mailbox; a bad or refused command prints one ``error:`` line
and changes nothing.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol, TextIO

from pyrt.commands._motion import motion_type_lines, parse_motion
from pyrt.commands.shell import CommandShell, parse_number, parse_seconds
from pyrt.errors import CommandError, FaultError
from pyrt.robots.axis import POLYAXIS, Axis
from pyrt.robots.paths import hare_path_record
from pyrt.robots.polyaxis import PolyAxis
from pyrt.robots.stops import StopReason
from pyrt.scheduler.motion import get_motion_type
from pyrt.scheduler.report import format_statistics

__all__ = ["OBJECT_COMMANDS", "ManipulatorShell"]

WAIT_TIMEOUT_S = 3600.0

#: Per object kind: command (lower case) -> (method, allowed argument counts, help).
OBJECT_COMMANDS: dict[str, dict[str, tuple[str, tuple[int, ...], str]]] = {
    "polyaxis": {
        "to": ("to", (3, 4), "to x y z [blend]: move the source to (x, y, z) cm; 'blend' "
               "joins the neck turn smoothly instead of stopping"),
        "tensionfind": ("tensionFind", (0,), "tensionFind: find and display the position "
                        "from the tensions"),
        "tensions": ("tensions", (0,), "tensions: find and display the desired tensions"),
        "netforce": ("netForce", (0, 3), "netForce [x y z]: net force magnitude at (x, y, z) "
                     "or at the current position"),
        "pattern": ("pattern", (1,), "pattern FILE: run through a pattern of endpoints "
                    "(first line: the log file)"),
        "stop": ("stop", (0,), "stop: stop all motors"),
        "tensionstop": ("tensionStop", (0,), "tensionStop: toggle stop-on-tension"),
        "errorsignalall": ("errorSignalAll", (0,), "errorSignalAll: toggle driving every "
                           "rope toward its equilibrium tension"),
    },
    "axis": {
        "up": ("up", (1,), "up DIST: move up DIST cm"),
        "down": ("down", (1,), "down DIST: move down DIST cm"),
        "to": ("to", (1,), "to LEN: change length to LEN cm"),
        "calibrate": ("calibrate", (0,), "calibrate: toggle loadcell calibration mode"),
        "point": ("point", (1, 2), "point LOAD: enter a loadcell calibration point"),
        "maxspeed": ("maxspeed", (1,), "maxspeed SPEED: set maximum motor speed in cm/s"),
        "zero": ("zero", (0,), "zero: reset encoder counter"),
        "stop": ("stop", (0,), "stop: stop the motor"),
    },
    "motor": {
        "maxspeed": ("maxspeed", (1,), "maxspeed SPEED: set maximum speed in cm/s"),
    },
    "encoder": {
        "reset": ("reset", (0,), "reset: reset counter to zero"),
        "read": ("read", (0,), "read: read and display value"),
        "readloop": ("readloop", (0,), "readloop: enter read/display loop"),
        "stoploop": ("stoploop", (0,), "stoploop: quit read/display loop"),
        "setzerolength": ("setZeroLength", (1,), "setZeroLength LEN: set zero length to "
                          "LEN cm"),
    },
    "loadcell": {
        "calibrate": ("calibrate", (0,), "calibrate: toggle calibration mode (leaving it "
                      "fits SLOPE and OFFSET and writes them back)"),
        "point": ("point", (1, 2), "point LOAD: a calibration point with LOAD (N, lb or kg) "
                  "hung on the rope"),
    },
    "av": {
        "show": ("show", (0,), "show: the vessel's geometry and pose (the AV takes no "
                 "other command)"),
    },
}

#: Device commands accepted while their axis is under PolyAxis control.
_READ_ONLY = {"read", "readloop", "stoploop"}

#: Commands that start motion (refused while a fault is not acknowledged).
_MOTION = {("polyaxis", "to"), ("polyaxis", "pattern"), ("axis", "up"), ("axis", "down"),
           ("axis", "to")}


class Runner(Protocol):
    """What the interpreter needs of :class:`pyrt.scheduler.runner.Runner`."""

    loop: Any

    def call(self, fn: Callable[..., Any], *args: Any, timeout_s: float = 1.0) -> Any: ...

    def wait_until(self, predicate: Callable[[], bool], timeout_s: float) -> bool: ...

    def sleep(self, seconds: float) -> None: ...

    def spawn(self, name: str, gen: Any, timeout_s: float = 1.0) -> Any: ...

    def submit_motion(self, record: Any, timeout_s: float = 1.0) -> int: ...


class ManipulatorShell(CommandShell):
    """The ``pyrt manipulator`` interpreter.

    ``station`` is a :class:`pyrt.station.manipulator.ManipulatorStation`
    run by ``runner`` (a :class:`pyrt.scheduler.runner.Runner` of its loop).
    """

    def __init__(self, runner: Runner, station: Any, stdout: TextIO):
        super().__init__(stdout)
        self.runner = runner
        self.station = station
        self.pa: PolyAxis = station.polyaxis
        self.pattern_job: Any = None

    @property
    def prompt(self) -> str:  # type: ignore[override]
        return f"{self.pa.name}> "

    # -- dispatch -----------------------------------------------------------------

    def onecmd(self, line: str) -> bool:
        """Run one line; True when the session should end (``quit``)."""
        return self.guarded(self._dispatch, line)

    def _dispatch(self, line: str) -> bool:
        words = line.split()
        if not words:
            return False
        word = words[0]
        fn = self.handler(word)
        if fn is not None:
            return bool(fn(line.strip()[len(word):].strip()))
        obj = self.station.objects.get(word.lower())
        if obj is None:
            self.error(f"unknown command or object {word!r}; objects: "
                       f"{', '.join(self.station.names())}; type help")
            return False
        self.object_command(obj, words[1:])
        return False

    def fault(self, exc: FaultError) -> None:
        self.say(f"FAULT: {exc.fault.cause} (in {exc.fault.source or self.pa.name}); "
                 "every motor stopped; give 'ack' to acknowledge")

    def kind(self, obj: object) -> str:
        """The command table an object answers to."""
        st = self.station
        if obj is self.pa:
            return "polyaxis"
        if isinstance(obj, Axis):
            return "axis"
        for a in st.axes:
            if obj is a.motor:
                return "motor"
            if obj is a.encoder:
                return "encoder"
            if obj is a.loadcell:
                return "loadcell"
        return "av"

    def owner(self, device: object) -> Axis:
        """The Axis a Motor, Encoder or Loadcell belongs to."""
        for a in self.station.axes:
            if device in (a.motor, a.encoder, a.loadcell):
                return a
        raise CommandError(f"{getattr(device, 'name', device)} belongs to no axis")

    def object_command(self, obj: Any, words: list[str]) -> None:
        """``OBJECT COMMAND ARGS...`` (Hardware::doCommand)."""
        kind = self.kind(obj)
        table = OBJECT_COMMANDS[kind]
        if not words:
            raise CommandError(f"{obj.name}: a command is needed; "
                               f"one of {', '.join(m for m, _, _ in table.values())}")
        key, args = words[0].lower(), words[1:]
        entry = table.get(key)
        if entry is None:
            raise CommandError(f"{obj.name}: unknown command {words[0]!r}; expected one of "
                               f"{', '.join(m for m, _, _ in table.values())}")
        method, counts, _help = entry
        if len(args) not in counts:
            raise CommandError(f"{obj.name} {method}: takes "
                               f"{' or '.join(map(str, counts))} argument(s), got {len(args)}")
        if (kind, key) in _MOTION:
            self.runner.call(self.station.check_ready, f"{obj.name} {method}")
        if kind == "axis" and key == "stop" and self.runner.call(lambda: self.pa.active):
            # one joint stopped stops the whole manipulator
            self.runner.call(self.pa.halt, StopReason.STOP, f"{obj.name} stop command")
            self.say(f"{obj.name}: stopped; the {self.pa.name} move is stopped with it")
            return
        if kind in ("motor", "encoder", "loadcell") and key not in _READ_ONLY:
            owner = self.owner(obj)
            if self.runner.call(lambda: owner.mode == POLYAXIS):
                raise CommandError(f"{obj.name} {method}: {owner.name} is under {self.pa.name} "
                                   "control (000: polyActivate turns off its commands); "
                                   "stop the move first")
        if kind == "polyaxis":
            if key == "pattern":
                self.start_pattern(args[0])
                return
            if key == "to":
                self.queue_move(args)
                return
            self.say(str(self.runner.call(self.pa.command, key, *args)))
            return
        if kind == "av":
            av = obj
            self.say(f"{av.name}: vessel radius {av.vessel_radius:g} cm, neck ring at "
                     f"{tuple(round(c, 2) for c in av.neck_ring_position)} radius "
                     f"{av.neck_ring_radius:g} cm, neck radius {av.neck_radius:g} cm, length "
                     f"{av.neck_length:g} cm; pose {av.position} {av.orientation}")
            return
        if method == "point":
            args = [" ".join(args)]  # a load may carry its unit: point 5 kg
        fn: Callable[..., Any] = getattr(obj, method)
        result = self.runner.call(fn, *args)
        self._report(obj, kind, method, result)

    def _report(self, obj: Any, kind: str, method: str, result: Any) -> None:
        name = obj.name
        if kind == "axis" and method in ("up", "down", "to"):
            self.say(f"{name}: moving to length {result:.3f} cm")
        elif method == "maxspeed":
            self.say(f"{name}: maximum speed {result:g} cm/s")
        elif kind == "axis" and method == "zero":
            self.say(f"{name}: encoder counter reset")
        elif kind == "axis" and method == "stop":
            self.say(f"{name}: stopped")
        elif kind == "encoder" and method in ("reset", "readloop", "stoploop"):
            self.say(f"{name}: {method}")
        elif kind == "encoder" and method == "setZeroLength":
            self.say(f"{name}: zero length {result:.3f} cm")
        # read, calibrate and point print through the device itself

    def queue_move(self, args: list[str]) -> None:
        """``to x y z [blend]``: checked now (a refusal moves nothing), then put on
        the motion queue as a record; it starts when the move before it ends."""
        pa = self.pa
        mode = args[3].lower() if len(args) == 4 else ""
        if mode not in ("", "blend", "stop"):
            raise CommandError(f"{pa.name} to: the fourth word may be 'blend' or 'stop', "
                               f"got {args[3]!r}")
        target = pa.parse_point(args[:3], "to")
        job = self.pattern_job
        if job is not None and not job.done:
            raise CommandError(f"{pa.name} to: a pattern is running ('{pa.name} stop' ends "
                               "it); nothing moved")
        self.runner.call(pa.check_target, target)
        waiting = self.runner.call(lambda: pa.active or len(self.station.motion) > 0)
        n = self.runner.submit_motion(hare_path_record(target, blend=mode == "blend"))
        x, y, z = target
        if waiting:
            self.say(f"{pa.name}: to ({x:g}, {y:g}, {z:g}) queued ({n} waiting)")
        else:
            self.say(f"{pa.name}: to ({x:g}, {y:g}, {z:g})")

    def start_pattern(self, path: str) -> None:
        """``pattern FILE``: read the file here, run the pattern as a loop job."""
        job = self.pattern_job
        if job is not None and not job.done:
            raise CommandError(f"{self.pa.name} pattern: a pattern is already running")
        if self.runner.call(self.station.busy):
            raise CommandError(f"{self.pa.name} pattern: a move is running; wait for it or "
                               "stop it first")
        gen = self.station.pattern_job(path)
        self.pattern_job = self.runner.spawn("pattern", gen)
        self.say(f"{self.pa.name}: pattern {path} started; log {self.station.pattern_log}")

    # -- the words ----------------------------------------------------------------

    def do_motion(self, arg: str) -> None:
        """motion [TYPE key=value ...]: queue a motion of any registered type; alone: list them.

        Values are numbers where they parse as numbers (motion hare_path x=0
        y=0 z=120 blend=0 is 'to 0 0 120').  A type with a check(robot,
        params) class method is checked now (a refusal moves nothing); the
        stop conditions apply to every motion."""
        record = parse_motion(arg)
        if record is None:
            self.say("motion types (motion TYPE key=value ...):")
            for line in motion_type_lines():
                self.say(line)
            return
        pa = self.pa
        self.runner.call(self.station.check_ready, f"motion {record.type}")
        job = self.pattern_job
        if job is not None and not job.done:
            raise CommandError(f"motion {record.type}: a pattern is running ('{pa.name} stop' "
                               "ends it); nothing moved")
        check = getattr(get_motion_type(record.type), "check", None)
        if callable(check):
            self.runner.call(check, pa, record.params)
        waiting = self.runner.call(lambda: pa.active or len(self.station.motion) > 0)
        n = self.runner.submit_motion(record)
        if waiting:
            self.say(f"{pa.name}: motion {record.type} queued ({n} waiting)")
        else:
            self.say(f"{pa.name}: motion {record.type}")

    def do_help(self, arg: str) -> None:
        """help [object]: list the commands, or one object's commands."""
        topic = arg.strip()
        if topic:
            obj = self.station.objects.get(topic.lower())
            if obj is not None:
                self.say(f"{obj.name} commands:")
                for _m, _c, text in OBJECT_COMMANDS[self.kind(obj)].values():
                    self.say(f"  {text}")
                return
            text = self.help_text(topic)
            if text is None:
                self.error(f"no help for {topic!r}")
            else:
                self.say(text)
            return
        self.say("commands: OBJECT COMMAND [ARGS] (names case-insensitive); objects:")
        self.say("  " + " ".join(self.station.names()))
        self.say("words:")
        for _name, line in self.commands():
            self.say(f"  {line}")
        self.say("'help OBJECT' lists an object's commands, e.g. help axis0")

    def do_quit(self, arg: str) -> bool:
        """quit: stop all motors, then exit."""
        try:
            self.runner.call(self.station.stop_all)
        except FaultError:
            self.runner.call(self.station.stop_all)
        return True

    def do_wait(self, arg: str) -> None:
        """wait [SECONDS]: wait until the move (or pattern, or axis move) ends; say why."""
        timeout = parse_seconds(arg, "wait") if arg.strip() else WAIT_TIMEOUT_S
        st, pa = self.station, self.pa

        def busy() -> bool:
            job = self.pattern_job
            return (st.busy() or (job is not None and not job.done)
                    or any(a.mode == "standalone" and a.motor.running for a in st.axes))

        axis_moves = self.runner.call(
            lambda: [a for a in st.axes if a.mode == "standalone" and a.motor.running])
        if not self.runner.call(busy):
            last = self.runner.call(lambda: pa.last_stop)
            self.say(f"nothing to wait for; last stop: {last}" if last else
                     "nothing to wait for")
            return
        try:
            done = self.runner.wait_until(lambda: not busy(), timeout)
        except FaultError as exc:
            self.fault(exc)
            return
        if not done:
            self.say(f"still moving after {timeout:g} s")
            return
        job = self.pattern_job
        if job is not None and job.done:
            self.pattern_job = None
            if job.error is not None:
                self.error(f"pattern failed: {job.error}")
            else:
                self.say(f"pattern finished: {len(job.result or [])} endpoints; log "
                         f"{st.pattern_log}")
        if axis_moves and not self.runner.call(lambda: pa.active):
            for a in axis_moves:
                length = self.runner.call(a.getLength)
                self.say(f"{a.name}: move ended at length {length:.3f} cm")
            return
        last = self.runner.call(lambda: pa.last_stop)
        self.say(str(last) if last is not None else "ended")

    def do_sleep(self, arg: str) -> None:
        """sleep SECONDS: let the controller run that long (loop time)."""
        self.runner.sleep(parse_seconds(arg, "sleep"))

    def do_stats(self, arg: str) -> None:
        """stats: per-task timing of the loop (calls, mean, p99, max, overruns)."""
        self.say(format_statistics(self.runner.statistics()))

    def do_status(self, arg: str) -> None:
        """status: source position, distErr, residual net force, tensions, time."""
        self.say(self.runner.call(self.station.status))

    def do_ack(self, arg: str) -> None:
        """ack: acknowledge a fault (the motors stay stopped; control polls resume)."""
        for _ in range(8):
            try:
                self.say(self.runner.call(self.station.acknowledge))
                return
            except FaultError as exc:
                self.fault(exc)

    def do_debug(self, arg: str) -> None:
        """debug: toggle the debugging state (a status line every second)."""
        on = self.runner.call(_toggle_debug, self.pa)
        self.say(f"debugging {'on' if on else 'off'}")

    def do_log(self, arg: str) -> None:
        """log [FILE]: toggle logging of per-axis state and rule outputs every poll.

        The default file is manipulator.log in the station directory; split
        it with 'pyrt logsort FILE'."""
        st = self.station
        if self.runner.call(lambda: st.polyaxis.log is not None):
            path = self.runner.call(st.stop_log)
            self.say(f"logging off; log written to {path}")
            return
        path = Path(arg.strip()) if arg.strip() else st.directory / "manipulator.log"
        self.say(f"logging on: {self.runner.call(st.start_log, path)}")

    def do_sim(self, arg: str) -> None:
        """sim [fault ROPE slip [FRACTION]|dead|stuck|stall|break|none]: the simulated world.

        With no argument, where the source really is and the true tensions.
        ROPE is an axis name (axis1) or index."""
        plant = self.station.plant
        parts = arg.split()
        if not parts:
            pos, t, wrapped = self.runner.call(
                lambda: (plant.position, plant.tensions(), plant.wrapped()))
            ring = [a.name for a, w in zip(self.station.axes, wrapped, strict=True) if w]
            self.say(f"true position ({pos[0]:.2f}, {pos[1]:.2f}, {pos[2]:.2f}) cm; tensions "
                     + " ".join(f"{v:.2f}" for v in t) + " N"
                     + (f"; on the neck ring: {', '.join(ring)}" if ring else ""))
            return
        if parts[0].lower() != "fault" or len(parts) < 3:
            raise CommandError("sim fault ROPE slip [FRACTION]|dead|stuck|stall|break|none")
        rope, what, rest = parts[1], parts[2].lower(), parts[3:]
        key: int | str = int(rope) if rope.isdigit() else rope
        actions: dict[str, Callable[..., None]] = {
            "slip": plant.inject_slip, "dead": plant.inject_loadcell_dead,
            "stuck": plant.inject_loadcell_stuck, "stall": plant.inject_stall,
            "break": plant.break_rope, "none": plant.clear_faults,
        }
        if what not in actions:
            raise CommandError(f"sim fault: unknown fault {what!r}; slip, dead, stuck, stall, "
                               "break or none")
        args: list[Any] = [key]
        if what == "slip" and rest:
            args.append(parse_number(rest[0], "slip fraction"))
        elif rest:
            raise CommandError(f"sim fault {what}: takes no more arguments")

        def apply() -> None:
            try:
                actions[what](*args)
            except ValueError as exc:
                raise CommandError(str(exc)) from None

        self.runner.call(apply)
        self.say(f"sim: {what} on {rope}")


def _toggle_debug(pa: PolyAxis) -> bool:
    pa.debug = not pa.debug
    return pa.debug
