"""The ``scope`` command of both consoles (004's software oscilloscope).

::

    scope                          status, channels on the scope, channels available
    scope add CH [CH ...]          add channels (names as the robot's resolver knows them)
    scope remove CH                remove a channel
    scope trigger CH LEVEL [rising|falling] [pre FRACTION]
    scope trigger off              no trigger
    scope every N                  sample every N ticks
    scope run [normal|auto|roll]   start acquiring; scope single: one triggered frame
    scope stop                     stop acquiring
    scope show [N]                 print the last N samples of the latest frame
    scope save FILE.csv|FILE.npz   export the latest frame
    scope plot FILE.png            draw the latest frame (needs matplotlib)

Every change to the scope runs in the loop thread through the runner; files
are written outside it.
"""

from __future__ import annotations

import shlex
from collections.abc import Callable
from typing import Any, TextIO

from pyrt.commands.shell import parse_number
from pyrt.errors import CommandError
from pyrt.scope import MODES, Frame, Scope, Source, plot_frame, save_frame

__all__ = ["ScopeCommand"]


class ScopeCommand:
    """Parses and runs ``scope ...`` lines for one console."""

    def __init__(
        self,
        runner: Any,
        scope: Scope,
        resolve: Callable[[str], Source],
        available: Callable[[], list[str]],
        stdout: TextIO,
    ):
        self.runner = runner
        self.scope = scope
        self.resolve = resolve
        self.available = available
        self.stdout = stdout

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
                "run, single, stop, show, save, plot, list"
            )
        handler(rest)

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

    def _do_trigger(self, rest: list[str]) -> None:
        if len(rest) == 1 and rest[0].lower() == "off":
            self._call(self.scope.clear_trigger)
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

    def _do_every(self, rest: list[str]) -> None:
        if len(rest) != 1 or not rest[0].isdigit():
            raise CommandError("scope every: a whole number of ticks, 1 or more")
        n = int(rest[0])

        def set_every() -> None:
            self.scope.every = n

        self._call(set_every)

    def _do_run(self, rest: list[str]) -> None:
        if len(rest) > 1 or (rest and rest[0].lower() not in MODES):
            raise CommandError(f"scope run: mode one of {', '.join(MODES)}")
        self._call(self.scope.run, rest[0].lower() if rest else None)

    def _do_single(self, rest: list[str]) -> None:
        if rest:
            raise CommandError("scope single takes no arguments")
        self._call(self.scope.single)

    def _do_stop(self, rest: list[str]) -> None:
        self._call(self.scope.stop)

    def _frame(self) -> Frame:
        frame = self._call(self.scope.read)
        if frame is None:
            raise CommandError("scope: nothing captured yet (scope run, then let time pass)")
        return frame

    def _do_show(self, rest: list[str]) -> None:
        n = 10
        if rest:
            if len(rest) != 1 or not rest[0].isdigit():
                raise CommandError("scope show: a number of samples")
            n = int(rest[0])
        frame = self._frame()
        self.say("t_s " + " ".join(frame.channels))
        for t, row in zip(frame.t_ns[-n:], frame.data[-n:], strict=True):
            self.say(f"{t / 1e9:.6f} " + " ".join(f"{v:.6g}" for v in row))

    def _do_save(self, rest: list[str]) -> None:
        if len(rest) != 1:
            raise CommandError("scope save: one file name ending .csv or .npz")
        frame = self._frame()
        path = save_frame(frame, rest[0])
        n = frame.data.shape[0]
        whole = "" if n == self.scope.capacity else f" (a partial frame: of {self.scope.capacity})"
        self.say(f"saved {n} samples of {len(frame.channels)} channel(s){whole} to {path}")

    def _do_plot(self, rest: list[str]) -> None:
        if len(rest) != 1:
            raise CommandError("scope plot: one .png file name")
        path = plot_frame(self._frame(), rest[0])
        self.say(f"plotted {path}")
