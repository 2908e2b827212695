"""One command interpreter for every robot: :class:`RobotShell` over a station.

A line is, in this order:

1. a **word** shared by every robot (``help``, ``wait``, ``sleep``,
   ``stats``, ``scope``, ``motion``, ``ack``, ``stop``, ``status``,
   ``get``, ``set``, ``quit``) or one of the station's own words (the manipulator's ``log``
   and ``debug``);
2. ``OBJECT [VERB [ARGS]]``: a command record of a component of the
   station's tree (``prototype to 0 0 50``, ``axis0Motor maxspeed 3``,
   ``sim fault jam``); an object alone runs its ``show`` or lists its verbs;
3. on a station with command **levels** (the gripper's ``CMD:`` and
   monitor), a letter of the current level with its argument, with or
   without a space (``P-1B86``).

Every record's grammar is checked here; its handler runs in the loop's
thread through **one** ``runner.call`` (the station checks the fault state
and acts in the same tick).  A handler's :class:`~pyrt.component.Switch`
changes the level; a returned loop :class:`~pyrt.scheduler.Job` is waited
for.  A bad or refused command prints one ``error:`` line and changes
nothing.  Help, completion and the server's privileges come from the same
records (:meth:`RobotShell.resolve`, :meth:`RobotShell.completions`).
"""

from __future__ import annotations

import shlex
import threading
from collections.abc import Callable
from typing import Any, TextIO

from pyrt.commands._lines import LineResolver, _did_you_mean
from pyrt.commands._motion import motion_type_lines, parse_motion
from pyrt.commands.scope import ScopeCommand
from pyrt.commands.shell import CommandShell, parse_seconds
from pyrt.commands.show import ShowWord
from pyrt.component import (
    Arg,
    Command,
    Component,
    Switch,
    command,
    reply_lines,
    run_prepared,
)
from pyrt.errors import CommandError, FaultError, MailboxTimeout, PyrtError
from pyrt.scheduler import Job
from pyrt.scheduler.report import format_statistics
from pyrt.scheduler.runner import FaultMessage
from pyrt.station.moves import MoveLine

__all__ = ["RobotShell"]

#: Longest a command's foreground job (init, calibration, pattern) may run, loop seconds.
JOB_TIMEOUT_S = 600.0
#: ``wait`` without a time.
WAIT_TIMEOUT_S = 3600.0
#: How often a piped console's ``wait`` says where the robot is (s of the station's
#: clock) unless told otherwise (``--wait-progress``).
WAIT_PROGRESS_S = 5.0

_REST = Arg("ARGS", str, optional=True, rest=True)


class RobotShell(LineResolver, CommandShell, ShowWord):
    """The interpreter of one station (see the module text).

    ``runner`` defaults to the station's; a read-only network client passes
    an observer runner instead.
    """

    #: Words that pass time and change nothing (not audited).
    _UNAUDITED = frozenset({"wait", "sleep", "help"})

    def __init__(self, station: Any, stdout: TextIO, runner: Any = None, source: str = "",
                 audit: Callable[[str, str], None] | None = None):
        super().__init__(stdout)
        self.station = station
        #: Where a remote source's commands that act are audited (the served
        #: station's trail), or None.
        self.audit = audit
        #: Who types into this shell: '' for the station's own console; a DAQ
        #: client or EPICS otherwise (each command of theirs that moves or
        #: changes the robot is shown on the console: :meth:`Station.audit`).
        self.source = source
        self.runner = runner if runner is not None else station.runner
        self.profile = station.profile
        self.level: Component | None = self.profile.level
        self._scope = ScopeCommand(self.runner, station.scope, self._channel,
                                   self._channel_names, stdout, self._channel_show,
                                   root=station.root)
        #: Fault events already shown to the operator (their ids), so each is shown once.
        self._shown: set[int] = set()
        self._shown_lock = threading.Lock()
        #: Move-ended events a wait of this shell has reported (their numbers).
        self._moves_shown: set[int] = set()
        #: A ``wait`` longer than this says where the robot is every this many
        #: seconds (of the station's clock), one line each, so that a script's
        #: log shows the move going; 0: it says nothing until the move ends
        #: (a terminal's console, the server's sessions).  The console of a
        #: piped run sets it (``--wait-progress``, :data:`WAIT_PROGRESS_S`).
        self.wait_progress_s = 0.0

    # -- prompt -----------------------------------------------------------------------

    @property
    def prompt(self) -> str:  # type: ignore[override]
        return self.profile.prompt_at(self.station.name, self.level)

    @property
    def in_monitor(self) -> bool:
        """The shell is at a level other than the station's first (the gripper's monitor)."""
        first = self.profile.level
        return self.level is not None and self.level is not first

    # -- dispatch ---------------------------------------------------------------------

    def onecmd(self, line: str) -> bool:
        """Run one line; True when the session should end (``quit``)."""
        return self.guarded(self._dispatch, line)

    def _dispatch(self, line: str) -> bool:
        if not line.strip():
            return False
        comp, rec, words, rest = self.resolve(line)
        try:
            args = rec.parse(words, rest)
        except CommandError as exc:  # "wiat" at the gripper's prompt is W with "iat"
            first = line.split()[0]
            hint = self._did_you_mean(first) if comp is self.level and len(first) > 1 else ""
            if hint:
                raise CommandError(f"{exc}{hint}") from None
            raise
        if (self.source and self.audit is not None and not rec.only_reads(words)
                and rec.name not in self._UNAUDITED):
            self.audit(self.source, line)
        if comp is None:
            return bool(rec.handler(*args))
        name = f"{comp.name} {rec.name}"
        if rec.prepare is not None:  # planned here, in this thread; the loop only enqueues
            result = run_prepared(rec, args, lambda arg: self.call(
                self.station.execute, comp, rec, [arg], name=name))
        else:
            result = self.call(self.station.execute, comp, rec, args, name=name)
        if isinstance(result, Job):
            result = self._wait_job(result)
            if result is None:
                return False
        plain = comp is self.level or comp is self.profile.words
        prefix = "" if plain or rec.name == "show" else comp.name
        self._show(rec, result, prefix)
        return False

    def call(self, fn: Callable[..., Any], *args: Any, name: str = "") -> Any:
        """One mailbox call; a fault reported by it is shown, then the command
        runs (a read is answered, a move refused by the station)."""
        try:
            return self.runner.call(fn, *args, name=name)
        except FaultError as exc:
            self.fault(exc)
        return self.runner.call(fn, *args, name=name)

    def _wait_job(self, job: Job) -> Any:
        if not self.runner.wait_until(lambda: job.done, JOB_TIMEOUT_S):
            self.runner.call(job.cancel)
            self.error(f"{job.name} did not finish within {JOB_TIMEOUT_S:g} s; stopped")
            return None
        if job.error is not None:
            raise job.error
        if job.result is None:
            self.error(f"{job.name} was abandoned (fault or stop)")
        return job.result

    def _show(self, rec: Command, result: Any, prefix: str = "") -> None:
        value = rec.reply(result) if rec.reply is not None else result
        if isinstance(value, Switch):
            for text in value.lines:
                self.say(text)
            level = self.station.component(value.level)
            notes = self.runner.call(level.enter_level)
            self.level = level
            for text in notes or []:
                self.say(text)
            return
        for text in reply_lines(value):
            if prefix and not text.lower().startswith(prefix.lower() + ":"):
                text = f"{prefix}: {text}"
            self.say(text)

    def fault(self, exc: FaultError, prefix: str = "FAULT") -> None:
        """Show a fault the loop raised at a command, unless the console has
        shown it already (:meth:`messages`): each fault once."""
        f = exc.fault
        with self._shown_lock:
            if f.id in self._shown:
                return
            self._shown.add(f.id)
        self.failures += 1
        self.say(f"{prefix}: {f.cause} (in {f.source or self.station.name})")
        self.say("every motor stopped; reads still answer; nothing moves until you type ack")

    def messages(self) -> list[str]:
        """The loop's asynchronous lines for the console (give the console
        this, not the runner's): a fault shown here is taken from the runner,
        so the next command does not report it again; one the shell has
        shown already is left out."""
        out: list[str] = []
        if self.source:  # a remote client's shell: the loop's lines are the console's
            return out
        for line in self.runner.messages():
            if isinstance(line, MoveLine):
                if line.seq not in self._moves_shown:
                    out.append(line)
                continue
            if isinstance(line, FaultMessage):
                with self._shown_lock:
                    if line.fault.id in self._shown:
                        continue
                    self._shown.add(line.fault.id)
                self.failures += 1
                self.runner.take_fault(line.fault)
                out.append(line)
                out.append("every motor stopped; reads still answer; nothing moves until you "
                           "type ack")
                continue
            out.append(line)
        return out

    # -- channels of the scope --------------------------------------------------------

    def _channel(self, name: str) -> Any:
        return self.station.resolve_signal(name).scope_source()

    def _channel_show(self, name: str) -> Callable[[Any], str] | None:
        show = self.station.resolve_signal(name).show
        return None if show is None else (lambda v: show(round(v)))

    def _channel_names(self) -> list[str]:
        root = self.station.root  # the scope's channels: the numbers (text is not sampled)
        names = [s.name for s in root.signals() if not s.is_text]
        names += [n for n, s in self.station.signals()
                  if not n.startswith(root.name + ".") and not s.is_text]
        if root.signal("ram:00") is not None:
            names.append("ram:XX")
        return names

    # -- the shared words -------------------------------------------------------------

    @command(_REST, name="help", reads_only=True, console=True)
    def do_help(self, arg: str = "") -> None:
        """help [command|object]: list the commands, or explain one."""
        topic = arg.strip()
        if topic:
            self._help_topic(topic)
            return
        level = self.level
        if level is not None:
            title = ("monitor commands (prompt *)" if self.in_monitor
                     else f"commands (prompt {self.prompt.strip()})")
            self.say(title + ":")
            for rec in level.commands():
                line = rec.summary
                same = line[:1].upper() == rec.name.upper()
                self.say(f"  {line}" if same else f"  {rec.name}  {line}")
        self.say("objects (OBJECT COMMAND [ARGS], names case-insensitive):")
        self.say("  " + " ".join(self.station.names()))
        self.say("words:")
        for w in self.words():
            self.say(f"  {w.summary}")
        if level is not None:
            self.say("numbers are hexadecimal; lower case is accepted; 'help X' explains X")
        else:
            self.say("'help OBJECT' lists an object's commands, e.g. help "
                     f"{self.station.names()[min(1, len(self.station.names()) - 1)]}")

    def _help_topic(self, topic: str) -> None:
        first, _, sub = topic.partition(" ")
        sub = sub.strip()
        if sub:
            self._help_sub(first, sub)
            return
        if len(topic) == 1 and self.level is not None:
            rec = self.level.find_command(topic)
            if rec is not None:
                self.say(rec.help)
                return
        w = self.word(topic)
        if w is not None:
            self.say(w.help)
            return
        comp = self.station.find(topic)
        if comp is not None:
            self.say(f"{comp.name} commands:")
            for rec in comp.commands():
                self.say(f"  {rec.summary}")
            sigs = self.station.signals_of(comp)
            if sigs:
                self.say("  signals: " + ", ".join(f"{s.name} ({s.units})" for s in sigs))
            return
        self.error(f"no help for {topic[:40]!r}{self._did_you_mean(topic)}")

    def _did_you_mean(self, text: str) -> str:
        """``" (did you mean 'wait'?)"`` for a near miss of a word or an object, or ''."""
        names = [n for w in self.words() for n in (w.name, *w.aliases)]
        names += self.station.names()
        return _did_you_mean(text, names)

    def _help_sub(self, first: str, sub: str) -> None:
        """``help OBJECT VERB`` (the verb's whole help) or ``help WORD SUB``
        (a sub-command of a word: ``help scope trigger``)."""
        comp = self.station.find(first)
        if comp is not None:
            rec = comp.find_command(sub.split()[0])
            if rec is None:
                raise CommandError(f"help {comp.name}: no command {sub[:40]!r}; it has "
                                   f"{', '.join(c.name for c in comp.commands()) or 'none'}")
            named = rec.help.split(" ", 1)[0].lower() == comp.name.lower()
            self.say(rec.help if named else f"{comp.name} {rec.help}")
            return
        w = self.word(first)
        if w is not None and w.name == "scope":
            self._scope.stdout = self.stdout
            self._scope(f"help {sub}")
            return
        if w is not None:
            raise CommandError(f"help {w.name}: {w.name} has no sub-commands; 'help {w.name}' "
                               "says what it takes")
        self.error(f"no help for {first[:40]!r}{self._did_you_mean(first)}")

    def _robot_word(self, arg: str) -> tuple[str | None, str]:
        """``NAME [REST]``: a robot's name and the rest, or (None, ``arg``) when the
        first word names no robot of the station."""
        first, _, rest = arg.strip().partition(" ")
        names = getattr(self.station, "robot_names", None)
        if first and names is not None and first.lower() in (n.lower() for n in names()):
            return first, rest.strip()
        return None, arg

    @command(_REST, name="wait", console=True)
    def do_wait(self, arg: str = "") -> None:
        """wait [ROBOT] [SECONDS]: wait until the current move (or job) ends; say why it ended.

        With several robots: every robot's moves, or ROBOT's alone."""
        robot, arg = self._robot_word(arg)
        timeout = parse_seconds(arg, "wait") if arg.strip() else WAIT_TIMEOUT_S
        profile = self.profile
        watch = self.call(self.station.watch_move, robot, name="wait")  # the one mailbox call
        if watch.idle:
            last = watch.last.reason if watch.last is not None else ""
            self.say(profile.idle_line(watch.where, last))
            return
        if watch.refusal:
            self.say(watch.refusal)
            return
        try:
            done = self._wait_for(watch, timeout, robot)
        except FaultError as exc:  # the fault says how the move ended
            self._moves_shown.update(e.seq for e in list(watch.ended))
            self.fault(exc, prefix=profile.fault_prefix)
            return
        finally:
            watch.waiting = False  # what ends from now on is said as it comes
        ended = list(watch.ended)
        self._moves_shown.update(e.seq for e in ended)
        for text in self.messages():
            self.say(text)  # what happened during the wait comes first, in order
        for event in ended:
            for text in event.report:
                self.say(text)
        if not done:
            self.say(f"still moving after {timeout:g} s")

    def _wait_for(self, watch: Any, timeout: float, robot: str | None) -> bool:
        """Wait for ``watch`` at most ``timeout`` s; every :attr:`wait_progress_s`
        of them (when set) one line says where the robot is, after what the loop
        said meanwhile."""
        every = self.wait_progress_s
        if not every > 0 or every >= timeout:
            return bool(self.runner.wait_until(lambda: watch.done, timeout))
        waited = 0.0
        while True:
            step = min(every, timeout - waited)
            if self.runner.wait_until(lambda: watch.done, step):
                return True
            waited += step
            if waited >= timeout:
                return False
            for text in self.messages():
                self.say(text)  # in the order they came, before the line
            where = self.runner.call(self.station.where, robot, name="where",
                                     take_fault=False)
            self.say(f"waiting, {waited:g} s: {where or 'moving'}")

    @command(Arg("SECONDS", str), name="sleep", console=True)
    def do_sleep(self, arg: str) -> None:
        """sleep SECONDS: let the controller run that long (loop time)."""
        self.runner.sleep(parse_seconds(arg, "sleep"))

    @command(name="stats", reads_only=True, console=True)
    def do_stats(self) -> None:
        """stats: per-task timing of the loop (calls, mean, p99, max, overruns)."""
        self.say(format_statistics(self.runner.statistics()))

    @command(_REST, name="scope", console=True,
             reads_only_subcommands=("list", "status", "show"))
    def do_scope(self, arg: str = "") -> None:
        """scope [add CH.. | trigger CH LEVEL | run | single | stop | show | save F | plot F]

        The software oscilloscope over any signal: OBJECT.SIGNAL (e.g.
        prototype.x, axis0.tension, sim.x), or a signal of the robot by its
        name alone (the gripper's encoder, dac ... and any RAM byte as
        ram:XX).  'scope' alone: its state and the channels there are."""
        self._scope.stdout = self.stdout
        self._scope(arg)

    @command(_REST, name="motion", moves=True, console=True)
    def do_motion(self, arg: str = "") -> None:
        """motion [TYPE key=value ...]: queue a motion of any registered type; alone: list them.

        Values are numbers where they parse as numbers.  A type with a
        check(robot, params) class method is checked before it is queued
        (a refusal moves nothing)."""
        record = parse_motion(arg)
        types = self.station.motion_types()
        if record is None:
            self.say(f"motion types of {self.station.name} (motion TYPE key=value ...):")
            for line in motion_type_lines(types):
                self.say(line)
            return
        self.station.motion_type(record.type)  # an unknown type: refused here, nothing queued
        n, waiting = self.call(self.station.submit_motion, record, name="motion")
        self.say(f"motion {record.type} queued ({n} waiting)"
                 + (" behind the running move" if waiting else ""))

    @command(Arg("ROBOT", str, optional=True), name="ack", console=True)
    def do_ack(self, robot: str | None = None) -> None:
        """ack [ROBOT]: acknowledge a fault: every motor stays stopped, the routines restart.

        With several robots: ack ROBOT acknowledges that robot's fault; ack
        alone, every robot's."""
        st = self.station
        if robot is not None:
            st.robot(robot)  # an unknown robot: refused here, nothing acknowledged
        for fault in self.runner.take_faults():  # each report is shown before it is acknowledged
            self.fault(FaultError(fault))
        for line in str(self.runner.call(st.acknowledge, robot, name="ack",
                                         take_fault=False)).splitlines():
            self.say(line)

    @command(Arg("ROBOT", str, optional=True), name="stop", console=True, anyone=True)
    def do_stop(self, robot: str | None = None) -> None:
        """stop [ROBOT]: stop every motor now, end the move, drop queued moves.

        With several robots: stop alone stops every robot; stop ROBOT, that one."""
        st = self.station
        if robot is None:
            said = self.runner.call(st.stop, name="stop", take_fault=False)
        else:
            st.robot(robot)  # an unknown robot: refused here
            said = self.runner.call(st.stop_robot, robot, name="stop", take_fault=False)
        for line in str(said).splitlines():
            self.say(line)

    @command(Arg("OBJECT", str, optional=True), name="status", reads_only=True, console=True)
    def do_status(self, name: str | None = None) -> None:
        """status [OBJECT]: the robot's status line (a line per robot), or every signal of
        OBJECT with units."""
        if name is None:
            for line in str(self.runner.call(self.station.status, name="status")).splitlines():
                self.say(line)
            return
        comp = self.station.component(name)
        sigs = self.station.signals_of(comp)
        values = self.runner.call(lambda: [(s, s.read()) for s in sigs])
        if not values:
            self.say(f"{comp.name}: no signals")
        for s, v in values:
            self.say(f"{comp.name}.{s.name} = {s.format(v)}")

    @command(name="statusline", reads_only=True, console=True)
    def do_statusline(self) -> None:
        """statusline: the robot's status line as the console shows it, in its radix (over
        the DAQ link, where STATUS gives the machine-readable fields: connect and top show it)."""
        self.say(self.runner.call(self.station.status, name="status"))

    def interrupt(self, at_prompt: bool) -> str:
        """Ctrl-C (the console calls it): a move that runs is stopped, every
        motor with it; idle at the prompt, a hint and nothing else."""
        st = self.station
        try:
            busy = self.runner.call(st.busy, name="interrupt", take_fault=False)
            if busy or not at_prompt:
                said = self.runner.call(st.stop, name="interrupt", take_fault=False)
                return f"interrupted: {said}" if busy else "interrupted; nothing was moving"
        except PyrtError as exc:
            return f"interrupted; could not reach the robot: {exc}"
        return "(Ctrl-C stops a move; nothing is moving: 'quit' or Ctrl-D leaves)"

    @command(Arg("NAME", str, optional=True), name="get", reads_only=True, console=True)
    def do_get(self, name: str | None = None) -> None:
        """get [OBJECT[.FIELD]]: a parameter with its units, range, whether it is written back.

        get OBJECT lists the object's parameters; get alone, the objects that have any."""
        st = self.station
        if name is None:
            have = self.runner.call(lambda: [(c.name, len(st.params_of(c)))
                                             for c in st.components()], name="get")
            listed = [f"{n} ({k})" for n, k in have if k]
            self.say("parameters (get OBJECT lists them): " + (", ".join(listed) or "none"))
            return
        if "." not in name:
            comp = st.component(name)
            rows = self.runner.call(lambda: [p.describe(comp.name, p.read())
                                             for p in st.params_of(comp)], name="get")
            if not rows:
                self.say(f"{comp.name}: no parameters")
            for row in rows:
                self.say(row)
            return
        comp, param = self.runner.call(st.param, name, name="get")
        self.say(self.runner.call(lambda: param.describe(comp.name, param.read()), name="get"))

    @command(Arg("NAME", str), Arg("VALUE", str), name="set", console=True)
    def do_set(self, name: str, value: str) -> None:
        """set OBJECT.FIELD VALUE: change a parameter at run time (get shows its range).

        Out of range, read only, or while a move runs where changing it then
        is unsafe: refused, nothing changed.  The line says whether the new
        value is written back to the database."""
        st = self.station
        comp, param = self.runner.call(st.param, name, name="set")
        v = param.parse(f"set {comp.name}.{param.name}", value)
        self.say(self.call(st.set_param, comp, param, v, name=f"set {comp.name}.{param.name}"))

    @command(name="clear", console=True, reads_only=True)
    def do_clear(self) -> None:
        """clear: clear the terminal screen (nothing on a pipe)."""
        isatty = getattr(self.stdout, "isatty", None)
        if callable(isatty) and isatty():
            self.stdout.write("\033[H\033[2J")
            self.stdout.flush()

    @command(name="quit", console=True, aliases=("exit",))
    def do_quit(self) -> bool:
        """quit (or exit): stop every motor, then leave."""
        try:
            self.runner.call(self.station.stop, name="quit", take_fault=False)
        except (MailboxTimeout, PyrtError) as exc:
            self.error(f"could not stop the motors: {exc}")
        return True


def split_words(text: str) -> list[str]:
    """Shell-like words (quotes group); CommandError on an unbalanced quote."""
    try:
        return shlex.split(text)
    except ValueError as exc:
        raise CommandError(str(exc)) from None
