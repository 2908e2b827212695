"""The ``scope`` command of both consoles (004's software oscilloscope).

Its help (:data:`SCOPE_HELP`, what ``help scope`` prints, and ``scope help
SUB`` for one sub-command) is kept here, beside the sub-commands it
describes.  Every change to the scope runs in the loop thread through the
runner and says what it did; files are written outside the loop.
"""

from __future__ import annotations

import shlex
import textwrap
from collections.abc import Callable
from typing import Any, TextIO

from pyrt.commands.shell import parse_number
from pyrt.errors import CommandError
from pyrt.scope import (
    MAX_BUFFER_BYTES,
    MAX_LENGTH,
    MODES,
    Frame,
    Scope,
    Source,
    check_plot_path,
    check_save_path,
    confine,
    plot_frame,
    save_frame,
)
from pyrt.scope.stream import DEFAULT_HZ, MAX_HZ, UdpStream, parse_udp_url

__all__ = ["MAX_SHOW", "SCOPE_HELP", "SUBCOMMAND_HELP", "ScopeCommand"]

#: The most samples one ``scope show`` prints (one request's work is bounded:
#: ``scope save`` writes a whole frame).
MAX_SHOW = 5000

#: One entry per sub-command: its usage and what it does.
SUBCOMMAND_HELP: dict[str, str] = {
    "status": "scope (or scope status, scope list): the state (with the pre-trigger fill "
              "while armed), the channels with their units, the trigger, the frames "
              "captured, and the channels there are",
    "add": "scope add CH [CH ...]: put channels on the scope (OBJECT.SIGNAL, or a signal "
           "of the robot by its name alone); all are added or none; capture restarts",
    "remove": "scope remove CH: take a channel off (and its trigger); capture restarts",
    "trigger": "scope trigger CH LEVEL [rising|falling] [pre FRACTION]: trigger when CH "
               "crosses LEVEL (default rising); FRACTION (0 <= f < 1, default 0.1) of the "
               "frame is kept from before the trigger point.  As on halscope, an armed "
               "scope first fills that pre-trigger part and arms the trigger only when it "
               "is full ('scope' shows how full): an event during the fill is not taken, "
               "and 'scope' says so.  scope trigger off: no trigger",
    "every": "scope every N: take a sample every N ticks (1..1000000)",
    "length": f"scope length N: the record length, N samples per channel "
              f"(2..{MAX_LENGTH}, and the buffer, (N + 64) x (channels + 1) x 8 bytes, "
              f"at most {MAX_BUFFER_BYTES // 2**20} MiB); capture restarts",
    "run": "scope run [normal|auto|roll|single]: start acquiring (default: the mode last "
           "used; auto on a fresh scope).  normal: a frame at each trigger; auto: also one "
           "per frame length without a trigger, and without a trigger set the latest "
           "samples as they come; roll: always the latest samples.  A frame shows as it "
           "fills: show, save and plot give the samples so far",
    "single": "scope single: arm for one triggered frame, then stop (needs a trigger)",
    "stop": "scope stop: stop acquiring; what was sampled stays readable (a partial "
            "frame if no frame was complete)",
    "show": f"scope show [N]: print the last N samples (default 10, at most {MAX_SHOW}) of "
            "the latest frame",
    "save": "scope save FILE.csv|FILE.npz|FILE.mcap: write the latest frame (the CSV "
            "header names each column with its units: encoder [counts]; MCAP, for Foxglove "
            "and PlotJuggler, needs pyrt[mcap]) into the working directory, or the one "
            "--scope-dir names (nowhere else)",
    "plot": "scope plot FILE.png|FILE.svg|FILE.pdf: draw the latest frame in the format "
            "the extension names (needs matplotlib)",
    "stream": "scope stream udp://HOST:PORT [HZ]: send the scope's channels live to "
              "PlotJuggler's UDP server (JSON protocol, timestamp field 'timestamp', loop "
              f"time in s), one object every 1/HZ s of loop time (default {DEFAULT_HZ:g}, "
              f"at most {MAX_HZ:g}) while the scope samples; the loop never waits for the "
              "network.  scope stream off: stop; scope stream: what it sent",
    "foxglove": "scope foxglove [PORT [HZ]]: serve the scope's channels live to Foxglove "
                "(ws://127.0.0.1:PORT, loopback only; default port 8765; at most HZ samples "
                "a second, default 50; with a server on, scope foxglove says what it sent): "
                "one JSON channel per object (/scope/OBJECT); for a "
                "robot that declares its joints also /joint_states (sensor_msgs/JointState) "
                "and /robot_description (its URDF), for the 3D panel (its joint signals are "
                "put on the scope).  Needs pyrt[foxglove].  scope foxglove off: stop",
    "help": "scope help [SUB]: this help, or one sub-command's",
}

#: ``help scope``: the word's usage, then every sub-command (lines of at most 96).
SCOPE_HELP = "\n".join([
    "scope [add|remove|trigger|every|length|run|single|stop|show|save|plot|stream|foxglove|"
    "help ...]",
    "",
    *textwrap.wrap("The software oscilloscope over any signal: OBJECT.SIGNAL (e.g. "
                   "prototype.x, axis0.tension, sim.x), or a signal of the robot by its name "
                   "alone (the gripper's encoder, dac ... and any RAM byte as ram:XX).", 96),
    *(line for text in SUBCOMMAND_HELP.values()
      for line in textwrap.wrap(text, 96, initial_indent="  ", subsequent_indent="      ")),
])


class ScopeCommand:
    """Parses and runs ``scope ...`` lines for one console."""

    def __init__(
        self,
        runner: Any,
        scope: Scope,
        resolve: Callable[[str], Source],
        available: Callable[[], list[str]],
        stdout: TextIO,
        display: Callable[[str], Callable[[Any], str] | None] | None = None,
        root: Any = None,
    ):
        self.runner = runner
        #: A channel's console format (``Signal.show``), or None: numbers as they are.
        self.display = display
        #: The robot's root component (its :attr:`~pyrt.Component.joint_states`), or None.
        self.root = root
        self.scope = scope
        self.resolve = resolve
        self.available = available
        self.stdout = stdout
        if scope.tick_ns is None:  # so that sample counts can be said as loop time
            scope.tick_ns = getattr(getattr(runner, "loop", None), "period_ns", None)

    def say(self, text: str) -> None:
        self.stdout.write(text + "\n")

    def verbs(self) -> list[str]:
        """The sub-commands, as the completion table offers them."""
        return ["list", "status", *(n[4:] for n in dir(self) if n.startswith("_do_"))]

    def __call__(self, arg: str) -> None:
        """Run one ``scope`` command line (without the word ``scope``)."""
        try:
            words = shlex.split(arg)
        except ValueError as exc:
            raise CommandError(f"scope: {exc}") from None
        if not words or words[0].lower() in ("list", "status"):
            self._status()
            return
        verb, rest = words[0].lower(), words[1:]
        handler = getattr(self, f"_do_{verb}", None)
        if handler is None:
            raise CommandError(
                f"scope: unknown sub-command {words[0]!r}; one of add, remove, trigger, every, "
                "length, run, single, stop, show, save, plot, stream, foxglove, list, help"
            )
        handler(rest)

    def _do_help(self, rest: list[str]) -> None:
        if not rest:
            self.say(SCOPE_HELP)
            return
        sub = rest[0].lower()
        sub = "status" if sub == "list" else sub
        if len(rest) > 1 or sub not in SUBCOMMAND_HELP:
            raise CommandError(f"scope help: no sub-command {' '.join(rest)[:40]!r}; one of "
                               f"{', '.join(SUBCOMMAND_HELP)}")
        self.say("\n".join(textwrap.wrap(SUBCOMMAND_HELP[sub], 96, subsequent_indent="    ")))

    def _call(self, fn: Callable[..., Any], *args: Any) -> Any:
        return self.runner.call(fn, *args, name=f"scope {getattr(fn, '__name__', '')}")

    def _status(self) -> None:
        self.say(self._call(self.scope.status))
        self.say("available: " + ", ".join(self.available()))

    def _do_add(self, rest: list[str]) -> None:
        if not rest:
            raise CommandError("scope add: name at least one channel (scope list shows them)")
        sources = [(name, self.resolve(name)) for name in rest]  # all resolve, or none is added
        for name, source in sources:
            self._call(self.scope.add, name, source)
        self.say(f"scope channels: {', '.join(self._call(lambda: self.scope.channels))}")

    def _do_remove(self, rest: list[str]) -> None:
        if len(rest) != 1:
            raise CommandError("scope remove: name one channel")
        self._call(self.scope.remove, rest[0])
        self.say(f"removed {rest[0]}; scope channels: "
                 f"{', '.join(self._call(lambda: self.scope.channels)) or '-'}")

    def _do_trigger(self, rest: list[str]) -> None:
        if len(rest) == 1 and rest[0].lower() == "off":
            self._call(self.scope.clear_trigger)
            self.say("trigger off" + self._after_change())
            return
        if len(rest) < 2:
            raise CommandError("scope trigger: CH LEVEL [rising|falling] [pre FRACTION], or 'off'")
        channel, level = rest[0], parse_number(rest[1], "trigger level")
        edge, pre = "rising", 0.1
        i = 2
        while i < len(rest):
            word = rest[i].lower()
            if word in ("rising", "falling"):
                edge = word
                i += 1
            elif word == "pre" and i + 1 < len(rest):
                pre = parse_number(rest[i + 1], "pre-trigger fraction")
                i += 2
            else:
                raise CommandError(f"scope trigger: unexpected {rest[i]!r}")
        self._call(self.scope.set_trigger, channel, level, edge, pre)
        sc = self.scope
        pre_n = self._call(lambda: sc.pre_samples)
        self.say(f"trigger: {self._call(sc.describe_trigger)}, {pre_n} samples"
                 f"{self._call(sc.seconds, pre_n)} before it (pre {pre:g}); the trigger arms "
                 "when that pre-trigger part has filled" + self._after_change())

    def _after_change(self) -> str:
        """What a change did to a running capture (it restarts)."""
        state = self._call(lambda: self.scope.state)
        return "" if state in ("stopped", "done") else f"; capture restarted ({state})"

    def _do_every(self, rest: list[str]) -> None:
        if len(rest) != 1 or not (rest[0].isascii() and rest[0].isdigit()):
            raise CommandError("scope every: a whole number of ticks, 1 or more")
        n = int(rest[0])

        def set_every() -> None:
            self.scope.every = n

        self._call(set_every)
        cap = self._call(lambda: self.scope.capacity)
        self.say(f"sampling every {n} tick(s){self._call(self.scope.seconds, 1, n)}; "
                 f"a frame of {cap} samples{self._call(self.scope.seconds, cap, n)}")

    def _do_length(self, rest: list[str]) -> None:
        if len(rest) != 1 or not (rest[0].isascii() and rest[0].isdigit()):
            raise CommandError(f"scope length: a whole number of samples, 2..{MAX_LENGTH}")
        self._call(self.scope.set_length, int(rest[0]))
        n = int(rest[0])
        self.say(f"record length {n} samples{self._call(self.scope.seconds, n)}"
                 + self._after_change())

    def _do_run(self, rest: list[str]) -> None:
        if len(rest) > 1 or (rest and rest[0].lower() not in MODES):
            raise CommandError(f"scope run: mode one of {', '.join(MODES)}")
        self._call(self.scope.run, rest[0].lower() if rest else None)
        self._started()

    def _do_single(self, rest: list[str]) -> None:
        if rest:
            raise CommandError("scope single takes no arguments")
        self._call(self.scope.single)
        self._started()

    def _started(self) -> None:
        """Say what a started scope does now."""
        sc = self.scope
        mode, cap = self._call(lambda: (sc.mode, sc.capacity))
        what = "one frame, then stops" if mode == "single" else (
            "the latest samples, always" if mode == "roll" else "a frame at each trigger"
            + (", or one per frame length without one" if mode == "auto" else ""))
        self.say(f"scope {mode}: {what}; frames of {cap} samples{self._call(sc.seconds, cap)}"
                 f"; {self._call(sc.waiting)}")

    def _do_stop(self, rest: list[str]) -> None:
        if rest:
            raise CommandError("scope stop takes no arguments")
        sc = self.scope
        was = self._call(lambda: sc.state)
        self._call(sc.stop)
        frame = self._call(sc.read)
        if frame is None:
            kept = "nothing was sampled"
        else:
            n = frame.data.shape[0]
            kept = (f"the latest frame ({n} samples) is kept" if n == sc.capacity
                    else f"a partial frame of {n} samples is kept")
        self.say(f"scope stopped (it was {was}); {kept}")

    def _frame(self, last: int | None = None) -> Frame:
        frame = self._call(self.scope.read, last)
        if frame is None:
            raise CommandError(f"scope: nothing captured yet: {self._call(self.scope.waiting)}")
        return frame

    def _do_show(self, rest: list[str]) -> None:
        n = 10
        if rest:
            if len(rest) != 1 or not (rest[0].isascii() and rest[0].isdigit()) \
                    or not 1 <= int(rest[0]) <= MAX_SHOW:
                raise CommandError(f"scope show: a number of samples, 1..{MAX_SHOW} (one "
                                   f"show prints at most {MAX_SHOW}; 'scope save FILE' "
                                   "writes the whole frame)")
            n = int(rest[0])
        frame = self._frame(n)
        shows = [self._show_of(name) for name in frame.channels]
        self.say("t_s " + " ".join(frame.channels))
        for t, row in zip(frame.t_ns[-n:], frame.data[-n:], strict=True):
            self.say(f"{t / 1e9:.6f} " + " ".join(
                show(v) if show is not None else f"{v:.6g}"
                for show, v in zip(shows, row, strict=True)))

    def _show_of(self, channel: str) -> Callable[[Any], str] | None:
        """How the console shows a value of ``channel`` (its robot's radix), or None."""
        if self.display is None:
            return None
        try:
            return self.display(channel)
        except CommandError:
            return None

    def _do_save(self, rest: list[str]) -> None:
        if len(rest) != 1:
            raise CommandError("scope save: one file name ending .csv, .npz or .mcap")
        check_save_path(rest[0])
        target = confine(rest[0], self.scope.directory, "scope save")
        frame = self._frame()
        path = save_frame(frame, target)
        n = frame.data.shape[0]
        whole = "" if n == self.scope.capacity else f" (a partial frame: of {self.scope.capacity})"
        self.say(f"saved {n} samples of {len(frame.channels)} channel(s){whole} to {path}")

    def _do_plot(self, rest: list[str]) -> None:
        if len(rest) != 1:
            raise CommandError("scope plot: one file name ending .png, .svg or .pdf")
        check_plot_path(rest[0])
        target = confine(rest[0], self.scope.directory, "scope plot")
        path = plot_frame(self._frame(), target)
        self.say(f"plotted {path}")

    def _do_stream(self, rest: list[str]) -> None:
        sc = self.scope
        if not rest:
            stream = self._call(lambda: sc.stream)
            self.say(stream.describe() if stream is not None else
                     "not streaming: scope stream udp://HOST:PORT [HZ] starts it")
            return
        if len(rest) == 1 and rest[0].lower() == "off":
            old = self._call(sc.stop_stream)
            if old is None:
                self.say("not streaming")
                return
            old.close()
            self.say(f"stream off; {old.describe()}")
            return
        if len(rest) > 2:
            raise CommandError("scope stream: udp://HOST:PORT [HZ], or 'off'")
        host, port = parse_udp_url(rest[0])
        hz = parse_number(rest[1], "scope stream: rate") if len(rest) == 2 else DEFAULT_HZ
        stream = UdpStream(host, port, hz)
        try:
            old = self._call(sc.start_stream, stream)
        except BaseException:
            stream.close()
            raise
        if old is not None:
            old.close()
        chans, state = self._call(lambda: (sc.channels, sc.state))
        note = ("" if state not in ("stopped", "done") else
                f"; the scope is {state}: 'scope run' starts the samples")
        self.say(f"streaming {', '.join(chans) or 'no channels yet'} to {stream.url} at "
                 f"{hz:g} Hz of loop time, PlotJuggler's UDP JSON (field 'timestamp': loop "
                 f"time, s){note}")

    def _do_foxglove(self, rest: list[str]) -> None:
        from pyrt.scope.foxglove import DEFAULT_HZ as FOX_HZ
        from pyrt.scope.foxglove import DEFAULT_PORT, FoxgloveServer

        sc = self.scope
        if not rest:
            server = self._call(lambda: sc.foxglove)
            if server is not None:
                self.say(server.describe())
                return
        if len(rest) == 1 and rest[0].lower() == "off":
            old = self._call(sc.stop_foxglove)
            if old is None:
                self.say("no Foxglove server")
                return
            old.close()
            self.say(f"Foxglove server off; {old.describe()}")
            return
        if len(rest) > 2 or (rest and (not (rest[0].isascii() and rest[0].isdigit())
                                      or not 0 <= int(rest[0]) <= 65535)):
            raise CommandError("scope foxglove: [PORT [HZ]] (PORT 1..65535, or 0 for any "
                               f"free one; default {DEFAULT_PORT}), or 'off'")
        port = int(rest[0]) if rest else DEFAULT_PORT
        hz = parse_number(rest[1], "scope foxglove: rate") if len(rest) == 2 else FOX_HZ
        joints = getattr(self.root, "joint_states", None)
        spec = None
        added: list[str] = []
        if joints is not None:
            sources = [(name, self.resolve(name)) for name in joints.signals()]
            have = self._call(lambda: sc.channels)
            for name, source in sources:
                if name not in have:
                    self._call(sc.add, name, source)
                    added.append(name)
            spec = (joints, [src.units for _n, src in sources])
        chans = self._call(lambda: list(sc.channels))
        units = {name: self.resolve(name).units for name in chans}
        server = FoxgloveServer(port, hz, units=units, joints=spec)
        try:
            old = self._call(sc.start_foxglove, server)
        except BaseException:
            server.close()
            raise
        if old is not None:
            old.close()
        state = self._call(lambda: sc.state)
        if state in ("stopped", "done") and chans:
            self._call(sc.run, None)
            state = "started (" + self._call(lambda: sc.mode) + ")"
        what = ", ".join(chans) or "no channels yet"
        note = f"; added {', '.join(added)} for /joint_states" if added else ""
        self.say(f"Foxglove server on {server.url}: {what} at {hz:g} Hz of loop time"
                 + (", /joint_states" + (" and /robot_description" if joints.urdf else "")
                    if joints is not None else "")
                 + f"{note}; the scope {state}")
