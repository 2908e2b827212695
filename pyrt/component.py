"""The one contract every controllable object of pyrt implements.

A :class:`Component` is what LinuxCNC HAL calls a component and
ros2_control a hardware interface plus its controller: a named object that
declares, once,

* its **signals**: named readable values with units (:class:`Signal`); the
  scope, ``status``, the server's STATUS/SUBSCRIBE and EPICS all read this
  one list;
* its **commands**: one :class:`Command` record each (name, handler,
  argument grammar, help from the handler's docstring, whether it reads only,
  whether it moves, whether it is allowed while the robot is faulted); help,
  completion and the server's privileges are derived from these records;
* its **children** (an Axis has a Motor, an Encoder and a Loadcell);
* its **tasks**: the self-scheduling routines it runs on a ready queue
  (:class:`pyrt.scheduler.Task` records: name, address, period, first run,
  body); the station registers every component's tasks from the tree;
* its **reflex**: what "stop everything now" means for it (a Motor disarms
  its channel and turns its windings off; the gripper nulls its drive
  current).  The station runs every component's reflex in the tick that
  found a fault, and on an operator ``stop``.

Commands are methods marked with :func:`command`; the grammar parses and
checks the words on the console's side, then the handler runs with the
parsed values in the loop's thread, in one mailbox call.  A command whose
work cannot be bounded (planning a move) declares a ``prepare`` step: it runs
in the caller's thread against a snapshot the loop copies, and the handler
only checks that snapshot still holds and acts (:func:`run_prepared`).  A handler's
return value is turned into reply lines by the record's ``reply`` (default:
``str(value)`` unless None).

A component speaks to the operator through :meth:`Component.say`: a
:class:`Message` (its source, a level, the text) handed to whoever the
station connected (:meth:`Component.connect`: the station publishes it to
the shell, the server and the log); a component no station has adopted yet
holds its messages until one does.  It reports a fault through
:meth:`Component.fail`, adopted or not: inside a station the station trips;
before adoption the component's own reflex runs and the failure is raised
(:class:`~pyrt.errors.FaultError`) to whoever is building it.

A handler may also return a :class:`Switch` (the console changes its
current command level, as the gripper's ``M`` enters the monitor) or a
loop :class:`~pyrt.scheduler.Job` (the console waits for it, as ``I`` waits
for the initialization).
"""

from __future__ import annotations

import contextlib
import functools
import inspect
import itertools
import math
import re
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, TypeVar

from pyrt.errors import CommandError, Fault, FaultError
from pyrt.scheduler.task import Task
from pyrt.scope import Source
from pyrt.scope.joints import JointStates
from pyrt.units import UnitError, parse_value, value_grammar

__all__ = [
    "MESSAGE_LEVELS",
    "PREPARE_TRIES",
    "SIGNAL_KINDS",
    "STRING_LENGTH",
    "Arg",
    "Command",
    "Component",
    "Limits",
    "Message",
    "Param",
    "Prepared",
    "Signal",
    "Snapshot",
    "Stale",
    "Switch",
    "command",
    "finite",
    "first_paragraph",
    "plain_text",
    "records_of",
    "reply_lines",
    "run_prepared",
    "serve_prepared",
    "walk",
    "word",
]


# -- signals --------------------------------------------------------------------------

_INF = math.inf


@dataclass(frozen=True)
class Limits:
    """A value's display range and alarm levels, as EPICS has them: ``lopr``..
    ``hopr`` (HOPR/LOPR), the major alarms ``lolo``/``hihi`` and the minor
    ones ``low``/``high`` (HIHI/HIGH/LOW/LOLO).  An alarm level at +-inf is off."""

    lopr: float
    hopr: float
    lolo: float = -_INF
    low: float = -_INF
    high: float = _INF
    hihi: float = _INF

    def __post_init__(self) -> None:
        values = (self.lopr, self.hopr, self.lolo, self.low, self.high, self.hihi)
        if any(math.isnan(v) for v in values) or not self.lopr <= self.hopr:
            raise ValueError(f"display range {self.lopr:g}..{self.hopr:g} is not a range")
        if not self.lolo <= self.low <= self.high <= self.hihi:
            raise ValueError("alarm levels must be LOLO <= LOW <= HIGH <= HIHI, got "
                             f"{self.lolo:g} {self.low:g} {self.high:g} {self.hihi:g}")

    def alarm(self, value: float) -> str:
        """``LOLO``, ``LOW``, ``HIGH`` or ``HIHI`` where ``value`` lies beyond a
        level (the major alarm first), else ''."""
        try:
            v = float(value)
        except (TypeError, ValueError):
            return ""
        if v <= self.lolo and self.lolo > -_INF:
            return "LOLO"
        if v >= self.hihi and self.hihi < _INF:
            return "HIHI"
        if v <= self.low and self.low > -_INF:
            return "LOW"
        if v >= self.high and self.high < _INF:
            return "HIGH"
        return ""

    @property
    def text(self) -> str:
        """``0..200`` and the alarm levels that are on (``LOLO 2, HIHI 200``)."""
        levels = [f"{n} {v:g}" for n, v in (("LOLO", self.lolo), ("LOW", self.low),
                                             ("HIGH", self.high), ("HIHI", self.hihi))
                  if math.isfinite(v)]
        rng = f"{self.lopr:g}..{self.hopr:g}"
        return f"{rng}; {', '.join(levels)}" if levels else rng


#: What a signal's value may be (:attr:`Signal.kind`): a number, or a line of text.
SIGNAL_KINDS = ("", "text")
#: The longest text an EPICS string PV holds (DBR_STRING: 40 bytes with its end).
STRING_LENGTH = 39


@dataclass(frozen=True)
class Signal:
    """A named readable value with units, read in the loop's thread.

    ``read`` returns the value; ``source`` is the scope's fast path to the
    same value (default: ``Source.call(read)``).  ``units`` is never empty:
    ``cm``, ``N``, ``counts``, ``bool``, ``byte`` ...  ``fmt`` formats a
    value for ``status`` (a format spec, as in ``format(value, fmt)``).
    ``limits`` is its display range and alarm levels (:class:`Limits`), or
    None: EPICS serves them as the PV's, ``status OBJECT`` shows them.
    ``show`` is how a console shows a value in its robot's radix (the
    gripper's counts: ``E47A (26.2 mm)``), or None: ``fmt`` and the units.

    ``kind`` is what the value is: ``""`` a number (or a bool: units
    ``bool``), ``"text"`` a line of text (:meth:`text`: where the robot is,
    how its last move ended).  A text signal is read and shown (``status``,
    ``show``, EPICS serves it as a string) but never sampled: the scope,
    the black box and the exports take numbers.  ``length`` bounds a text
    signal's value (characters; 0: no bound): EPICS serves a text of at
    most :data:`STRING_LENGTH` characters as a string PV, a longer or
    unbounded one as a char waveform, as an IOC does.
    """

    name: str
    units: str
    read: Callable[[], Any]
    doc: str = ""
    fmt: str = ".4g"
    source: Source | None = None
    limits: Limits | None = None
    show: Callable[[Any], str] | None = None
    kind: str = ""
    length: int = 0

    def __post_init__(self) -> None:
        if self.kind not in SIGNAL_KINDS:
            raise ValueError(f"signal {self.name!r}: kind {self.kind!r} is not one of "
                             f"{', '.join(repr(k) for k in SIGNAL_KINDS)}")
        if self.length < 0 or (self.length and self.kind != "text"):
            raise ValueError(f"signal {self.name!r}: a length bounds a text signal only "
                             f"(got {self.length!r})")

    @classmethod
    def text(cls, name: str, read: Callable[[], str], doc: str = "",
             length: int = 0) -> Signal:
        """A signal whose value is a line of text (``str(value)``; units ``text``),
        at most ``length`` characters when it is given."""
        return cls(name, "text", read, doc, "s", kind="text", length=length)

    @property
    def is_text(self) -> bool:
        """Its value is text (never sampled: the scope takes numbers)."""
        return self.kind == "text"

    @classmethod
    def attr(cls, name: str, units: str, obj: Any, attr: str, doc: str = "",
             fmt: str = ".4g", limits: Limits | None = None) -> Signal:
        """A signal that is an attribute of ``obj``."""
        return cls(name, units, lambda: getattr(obj, attr), doc, fmt, Source.attr(obj, attr),
                   limits)

    @classmethod
    def item(cls, name: str, units: str, seq: Any, index: int, doc: str = "",
             fmt: str = ".4g", limits: Limits | None = None) -> Signal:
        """A signal that is ``seq[index]`` (a list the loop updates in place)."""
        return cls(name, units, lambda: seq[index], doc, fmt, Source.item(seq, index), limits)

    def limited(self, limits: Limits | None) -> Signal:
        """The same signal with ``limits``."""
        return replace(self, limits=limits)

    def scope_source(self) -> Source:
        """Where the scope samples this signal; CommandError for a text signal
        (the scope samples numbers: ``status`` and ``show`` read text)."""
        if self.is_text:
            raise CommandError(f"{self.name} is text ({self.doc or 'a line of text'}): the "
                               "scope samples numbers; 'status' or 'show' reads it")
        src = self.source if self.source is not None else Source.call(self.read)
        return src.described(self.units, self.fmt)

    def format(self, value: Any) -> str:
        """``value`` as ``status`` shows it, with its units (or as :attr:`show` says;
        a text signal's value as it is)."""
        if self.is_text:
            return str(value) or "''"
        if self.show is not None:
            try:
                return self.show(value)
            except (TypeError, ValueError):
                pass
        try:
            text = format(value, self.fmt)
        except (TypeError, ValueError):
            text = str(value)
        return f"{text} {self.units}"


# -- parameters ---------------------------------------------------------------------


@dataclass(frozen=True)
class Param:
    """A tunable value read and changed by name at run time (HAL's parameters,
    halcmd's ``getp``/``setp``; the consoles' ``get``/``set``).

    ``read`` returns the value; ``write(value)`` changes it (loop thread; it may
    check more than the range and raise CommandError, changing nothing) and may
    return a line to say; None: read only.  ``lo``/``hi`` is the range in
    ``units`` (checked before ``write`` runs); ``integer`` values are whole,
    ``hex`` ones (the gripper's RAM bytes) are read and shown in hexadecimal.
    ``written_back``: the value is written to the station's database (it
    survives a restart); ``safe_while_moving``: it may change while a move
    runs (else ``set`` is refused then).
    """

    name: str
    units: str
    read: Callable[[], Any]
    write: Callable[[Any], Any] | None = None
    lo: float | None = None
    hi: float | None = None
    doc: str = ""
    written_back: bool = False
    safe_while_moving: bool = False
    integer: bool = False
    hex: bool = False

    @property
    def writable(self) -> bool:
        """Whether ``set`` may change it."""
        return self.write is not None

    def text(self, value: Any) -> str:
        """``value`` as ``get`` shows it (hex bytes as ``0C``)."""
        if self.hex:
            return f"{int(value):02X}"
        if self.integer:
            return f"{int(value):d}"
        try:
            return f"{float(value):.6g}"
        except (TypeError, ValueError):
            return str(value)

    @property
    def range_text(self) -> str:
        """``0..1000 N`` (hex: ``01..7F``); '' without a range."""
        if self.lo is None and self.hi is None:
            return ""
        u = f" {self.units}" if self.units else ""
        lo = "" if self.lo is None else self.text(self.lo)
        hi = "" if self.hi is None else self.text(self.hi)
        if self.lo is not None and self.hi is not None:
            return f"{lo}..{hi}{u}"
        return f">= {lo}{u}" if self.lo is not None else f"<= {hi}{u}"

    def parse(self, who: str, text: str) -> float | int:
        """``text`` as a value of this parameter, checked against its range;
        CommandError naming the range if not (nothing changed)."""
        t = text.strip()
        rng = f" ({self.range_text})" if self.range_text else ""
        try:
            if self.hex:
                if not re.fullmatch(r"[0-9A-Fa-f]+", t):  # int() takes other scripts'
                    raise ValueError(t)                     # digits, 0x and 1_0 too
                value: float | int = int(t, 16)
            else:
                value = parse_value(t, self.units)  # the one number-and-unit grammar
                if self.integer:
                    if not value.is_integer():
                        raise ValueError(t)
                    value = int(value)
        except (UnitError, ValueError):
            kind = "a hexadecimal number" if self.hex else (
                "a whole number" if self.integer else "a number")
            raise CommandError(f"{who}: {t[:40]!r} is not {kind}{rng}; nothing changed") from None
        if not math.isfinite(value):
            raise CommandError(f"{who}: {t[:40]!r} is not a finite number{rng}; nothing changed")
        if (self.lo is not None and value < self.lo) or (self.hi is not None and value > self.hi):
            raise CommandError(f"{who}: {self.text(value)} is out of range{rng}; nothing changed")
        return value

    def describe(self, owner: str, value: Any) -> str:
        """One line of ``get``: name, value, units, range, whether it is written
        back and when it may change."""
        u = f" {self.units}" if self.units else ""
        facts = [f"range {self.range_text}"] if self.range_text else []
        if not self.writable:
            facts.append("read only")
        else:
            facts.append("written back" if self.written_back else "not written back")
            if not self.safe_while_moving:
                facts.append("not while moving")
        doc = f": {self.doc}" if self.doc else ""
        return f"{owner}.{self.name} = {self.text(value)}{u} ({'; '.join(facts)}){doc}"


# -- command records ----------------------------------------------------------------


@dataclass(frozen=True)
class Arg:
    """One word of a command's grammar: ``parse(text)`` checks and converts it.

    ``optional`` arguments may be left out (the handler's default is used);
    ``rest`` takes the rest of the line as one text (a file name, a load
    with its unit, a ``key=value`` list).

    A numeric argument states its physical range: ``lo``/``hi`` (either may
    be None: unbounded that side) in ``units``; the value is checked against
    it before the handler runs, and help, the server and EPICS show it
    (:attr:`range_text`).  A range that depends on the object (a rope's
    length range) is named by ``bounds``: the attribute of the command's
    owner holding ``(lo, hi)``, read when the records are made
    (:func:`records_of`).
    """

    name: str
    parse: Callable[[str], Any] = str
    optional: bool = False
    rest: bool = False
    choices: tuple[str, ...] = ()
    lo: float | None = None
    hi: float | None = None
    units: str = ""
    bounds: str = ""
    #: What the range is (shown after it in help and in the refusal).
    what: str = ""

    @property
    def usage(self) -> str:
        """The argument as help shows it."""
        text = "|".join(self.choices) if self.choices else self.name
        if self.rest:
            text += " ..."
        return f"[{text}]" if self.optional else text

    @property
    def ranged(self) -> bool:
        """True when the argument has a lower or an upper bound."""
        return self.lo is not None or self.hi is not None

    @property
    def range_text(self) -> str:
        """``"LEN 150..700 cm"`` (``"DIST >= 0 cm"`` when one-sided); "" without a range."""
        if not self.ranged:
            return ""
        u = f" {self.units}" if self.units else ""
        if self.lo is not None and self.hi is not None:
            text = f"{self.name} {self.lo:g}..{self.hi:g}{u}"
        elif self.lo is not None:
            text = f"{self.name} >= {self.lo:g}{u}"
        else:
            text = f"{self.name} <= {self.hi:g}{u}"
        return f"{text} ({self.what})" if self.what else text

    def check(self, who: str, value: Any) -> Any:
        """``value`` if it is a finite number inside the range (CommandError naming
        the range if not; a text is read by the one number grammar,
        :func:`pyrt.units.parse_value`, in :attr:`units`); values of arguments
        without a range pass unchanged."""
        if not self.ranged:
            return value
        try:
            if isinstance(value, str):
                v = parse_value(value, self.units)
            elif isinstance(value, bool):
                raise TypeError(value)
            else:
                v = float(value)
        except (TypeError, ValueError):
            raise CommandError(f"{who}: {self.name} must be {value_grammar(self.units)} "
                               f"({self.range_text}), got {str(value)[:40]!r}") from None
        if (not math.isfinite(v) or (self.lo is not None and v < self.lo)
                or (self.hi is not None and v > self.hi)):
            raise CommandError(f"{who}: {self.name} {v:g} is out of range: {self.range_text}; "
                               "nothing changed")
        return v if isinstance(value, str) else value


def finite(what: str, lo: float = -math.inf, hi: float = math.inf,
           units: str = "") -> Callable[[str], float]:
    """A parser of a finite number in ``lo..hi`` ``units``, written as the one
    number grammar takes it (:func:`pyrt.units.parse_value`: a unit of the same
    quantity is converted); CommandError naming ``what`` and what it takes."""

    def parse(text: str) -> float:
        try:
            value = parse_value(text, units)
        except UnitError as exc:
            raise CommandError(f"{what} {text[:40]!r} is not a number: {exc}") from None
        if not lo <= value <= hi:
            raise CommandError(f"{what} {value:g} is out of range ({lo:g}..{hi:g})")
        return value

    parse.__name__ = f"finite_{what}"
    return parse


def word(*choices: str) -> Callable[[str], str]:
    """A parser of one of ``choices`` (case-insensitive; returns the lower-case word)."""

    def parse(text: str) -> str:
        w = text.lower()
        if w not in choices:
            raise CommandError(f"expected {' or '.join(choices)}, got {text[:40]!r}")
        return w

    return parse


@dataclass(frozen=True)
class Command:
    """One command of a component (see the module text)."""

    name: str
    handler: Callable[..., Any]
    args: tuple[Arg, ...] = ()
    help: str = ""
    reads_only: bool = False
    moves: bool = False
    while_faulted: bool = True
    #: Any client may give it, privileged or not (reads, and the operator stop).
    anyone: bool = False
    reply: Callable[[Any], Any] | None = None
    #: Runs on the console's side (a shell word that waits or sleeps), not in the loop.
    console: bool = False
    owner: str = ""
    #: For a word whose first argument is a sub-command: the sub-commands that only read.
    reads_only_subcommands: frozenset[str] = frozenset()
    #: Other names it answers to (000's long names beside the short ones).
    aliases: tuple[str, ...] = ()
    #: Ranges shown in help beside :attr:`ranges` that the grammar does not check
    #: (an argument named like a signal of its owner: that signal's display range).
    shown_ranges: tuple[str, ...] = ()
    #: Work that cannot be bounded (solving an inverse, planning a segment), done in the
    #: caller's thread, not in a loop tick: ``prepare(snapshot, *args)``; the handler then
    #: takes its result alone, in the loop (:func:`run_prepared`, :func:`serve_prepared`).
    #: None: the handler takes the parsed arguments.
    prepare: Callable[..., Any] | None = None
    #: What ``prepare`` needs of loop-owned state, copied in the loop (bounded), or None.
    snapshot: Callable[[], Any] | None = None

    def answers_to(self, name: str) -> bool:
        """True when ``name`` (any case) is this command's name or an alias."""
        key = name.lower()
        return key == self.name.lower() or key in (a.lower() for a in self.aliases)

    def only_reads(self, words: Sequence[str]) -> bool:
        """True when this command with ``words`` as its arguments only reads."""
        if self.reads_only:
            return True
        if self.reads_only_subcommands:
            return not words or words[0].lower() in self.reads_only_subcommands
        return False

    @property
    def summary(self) -> str:
        """The help's first paragraph as one line (a sentence is never cut at a
        line end), with the ranges of the numeric arguments."""
        line = first_paragraph(self.help) or self.name
        ranges = [*self.ranges, *self.shown_ranges]
        return f"{line.rstrip('.')} [{'; '.join(ranges)}]" if ranges else line

    @property
    def usage(self) -> str:
        """``name ARG [ARG]``."""
        return " ".join([self.name, *(a.usage for a in self.args)])

    @property
    def ranges(self) -> list[str]:
        """The ranges of the numeric arguments (``"LEN 150..700 cm"``)."""
        return [a.range_text for a in self.args if a.ranged]

    def parse(self, words: Sequence[str], rest_text: str = "") -> list[Any]:
        """The arguments of ``words`` checked and converted (CommandError if not)."""
        out: list[Any] = []
        # a letter of 002 speaks for itself ("W takes no argument")
        who = self.name if len(self.name) == 1 else f"{self.owner} {self.name}".strip()
        required = sum(1 for a in self.args if not a.optional)
        if self.args and self.args[-1].rest:
            if not rest_text and words:
                rest_text = " ".join(words)
            fixed = list(self.args[:-1])
            head = words[: len(fixed)]
            if len(head) < sum(1 for a in fixed if not a.optional):
                raise CommandError(f"{who}: usage: {self.usage}")
            for a, w in zip(fixed, head, strict=False):
                out.append(_parse_one(who, a, w))
            tail = rest_text
            for w in head:  # the rest of the line after the fixed words
                tail = tail.lstrip()[len(w):]
            tail = tail.strip()
            last = self.args[-1]
            if tail:
                out.append(_parse_one(who, last, tail))
            elif not last.optional:
                raise CommandError(f"{who}: usage: {self.usage}")
            return out
        if not required <= len(words) <= len(self.args):
            if not self.args:
                raise CommandError(f"{who} takes no argument (got {' '.join(words)[:40]!r})")
            n = (f"{required}" if required == len(self.args)
                 else f"{required} to {len(self.args)}")
            raise CommandError(f"{who}: takes {n} argument(s), got {len(words)}; "
                               f"usage: {self.usage}")
        for a, w in zip(self.args, words, strict=False):
            out.append(_parse_one(who, a, w))
        return out

    def lines(self, result: Any) -> list[str]:
        """The reply lines of a handler's result."""
        return reply_lines(self.reply(result) if self.reply is not None else result)


_ROLE = re.compile(r":[a-z]+(?::[a-z]+)?:`~?([^`]+)`")


def plain_text(text: str) -> str:
    """reST markup as a console or ``--help`` shows it: no double backticks,
    roles (``:class:`~pyrt.X```) as their target's name."""
    return _ROLE.sub(lambda m: m.group(1).rsplit(".", 1)[-1] if m.group(0).count("~")
                     else m.group(1), text).replace("``", "")


def first_paragraph(text: str) -> str:
    """The first paragraph of ``text`` (up to its first blank line) as one line,
    without reST markup; the range line records add ("Range: ...") is not part of it."""
    lines: list[str] = []
    for line in text.strip().splitlines():
        if not line.strip() or line.startswith("Range: "):
            break
        lines.append(line.strip())
    return plain_text(" ".join(lines))


def reply_lines(value: Any) -> list[str]:
    """A reply as lines: None is none, a string its lines, strings as they
    are, anything else its ``str``."""
    if value is None:
        return []
    if isinstance(value, str):
        return value.splitlines() or [""]
    if isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value):
        return list(value)
    return [str(value)]


def _parse_one(who: str, arg: Arg, text: str) -> Any:
    if arg.choices and text.lower() not in arg.choices:
        raise CommandError(f"{who}: {arg.name} must be {' or '.join(arg.choices)}, "
                           f"got {text[:40]!r}")
    if arg.ranged and arg.parse is str:  # a number in arg.units, converted here
        return arg.check(who, text)
    try:
        value = arg.parse(text)
    except CommandError:
        raise  # the parsers name what they parse

    except (TypeError, ValueError) as exc:
        raise CommandError(f"{who}: {arg.name}: {exc}") from None
    return arg.check(who, value)


_MARK = "__pyrt_command__"
#: A command handler, kept with its own signature by :func:`command`.
_F = TypeVar("_F", bound=Callable[..., Any])


def command(
    *args: Arg,
    name: str | None = None,
    reads_only: bool = False,
    moves: bool = False,
    while_faulted: bool | None = None,
    anyone: bool | None = None,
    reply: Callable[[Any], Any] | None = None,
    console: bool = False,
    reads_only_subcommands: Sequence[str] = (),
    aliases: Sequence[str] = (),
    prepare: str | None = None,
    snapshot: str | None = None,
) -> Callable[[_F], _F]:
    """Mark a method as a command; its docstring is its help.

    ``while_faulted`` defaults to "does not move"; ``anyone`` to
    ``reads_only``.  The method keeps working as a plain method.
    ``prepare`` and ``snapshot`` name methods of the same object (the
    record's :attr:`Command.prepare` and :attr:`Command.snapshot`); the marked
    method is then the loop's side, given what ``prepare`` returned.
    """

    def mark(fn: _F) -> _F:
        setattr(fn, _MARK, {
            "name": name or fn.__name__, "args": tuple(args), "reads_only": reads_only,
            "moves": moves, "while_faulted": (not moves) if while_faulted is None
            else while_faulted, "anyone": reads_only if anyone is None else anyone,
            "reply": reply, "console": console,
            "subs": frozenset(w.lower() for w in reads_only_subcommands),
            "aliases": tuple(aliases), "prepare": prepare, "snapshot": snapshot,
        })
        return fn

    return mark


@functools.cache
def _doc_of(fn: Callable[..., Any]) -> str:
    """A marked method's help text: its docstring, cleaned (the same every time a
    line is resolved, and cleaning it costs more than the rest of the record)."""
    return inspect.getdoc(fn) or ""


def _marked(obj: Any) -> dict[str, tuple[str, Any, dict[str, Any]]]:
    """The methods of ``obj`` marked with :func:`command`, by lower-case name, in
    the order the class defines them (base classes first, a subclass's method
    replacing its base's of the same name): ``(attribute, function, mark)``."""
    seen: dict[str, tuple[str, Any, dict[str, Any]]] = {}
    for klass in reversed(type(obj).__mro__):
        for attr, fn in vars(klass).items():
            spec = getattr(fn, _MARK, None)
            if spec is not None:
                seen[spec["name"].lower()] = (attr, fn, spec)
    return seen


def _record(obj: Any, owner: str, attr: str, fn: Any, spec: dict[str, Any]) -> Command:
    bound = getattr(obj, attr)
    doc = _doc_of(fn)
    args = tuple(_bind_range(a, obj) for a in spec["args"])
    shown = tuple(_signal_range(a, obj, owner) for a in args if not a.ranged)
    shown = tuple(t for t in shown if t)
    ranges = [*(a.range_text for a in args if a.ranged), *shown]
    if ranges:
        doc += ("\n" if doc else "") + "Range: " + "; ".join(ranges) + "."
    return Command(
        spec["name"], bound, args, doc, spec["reads_only"], spec["moves"],
        spec["while_faulted"], spec["anyone"], spec["reply"], spec["console"], owner,
        spec["subs"], spec["aliases"], shown,
        getattr(obj, spec["prepare"]) if spec.get("prepare") else None,
        getattr(obj, spec["snapshot"]) if spec.get("snapshot") else None)


def records_of(obj: Any, owner: str = "") -> list[Command]:
    """The :class:`Command` records of the methods of ``obj`` marked with
    :func:`command`, in the order the class defines them (base classes first)."""
    return [_record(obj, owner, *m) for m in _marked(obj).values()]


def record_named(obj: Any, name: str, owner: str = "") -> Command | None:
    """The first of :func:`records_of` that answers to ``name`` (any case), or
    None: the same record, made alone (a line names one command; making every
    record of the object to find it cost more than the rest of resolving it)."""
    key = name.lower()
    for attr, fn, spec in _marked(obj).values():
        if key == spec["name"].lower() or key in (a.lower() for a in spec["aliases"]):
            return _record(obj, owner, attr, fn, spec)
    return None


class Stale(CommandError):
    """A prepared command's snapshot no longer holds when the loop takes its
    result (something was queued or stopped in between): prepared again."""


#: How many times :func:`run_prepared` prepares a command whose snapshot went stale.
PREPARE_TRIES = 3
#: Snapshots the loop keeps for the hand-overs to come (a replay prepares from them).
KEPT_SNAPSHOTS = 16
_tokens = itertools.count(1)


@dataclass(frozen=True)
class Snapshot:
    """The argument that asks a prepared record for its snapshot (number ``id``)."""

    id: int


@dataclass(frozen=True)
class Prepared:
    """The argument that hands a prepared record's ``work`` to its handler: what
    ``prepare`` made of ``args`` from snapshot ``id``.  A journal keeps ``id``
    and ``args`` (not ``work``): a replay prepares again from the snapshot the
    loop took at the same tick."""

    id: int
    args: tuple[Any, ...]
    work: Any = field(default=None, init=False, compare=False)


def run_prepared(record: Command, args: Sequence[Any], call: Callable[[Any], Any]) -> Any:
    """Run ``record`` (one with :attr:`Command.prepare`) with its checked ``args``:
    ``call(arg)`` runs the record in the loop with ``[arg]`` as its arguments (one
    mailbox call through the station's ``execute``, which :func:`serve_prepared`
    answers): first a :class:`Snapshot` (the loop copies what ``prepare``
    needs), then ``prepare`` runs here, in the caller's thread, then a
    :class:`Prepared` hands its result to the handler, which checks that the
    snapshot still holds (else :class:`Stale`: prepared again, at most
    :data:`PREPARE_TRIES` times, then refused; nothing moved)."""
    assert record.prepare is not None
    for _ in range(PREPARE_TRIES):
        token = Snapshot(next(_tokens))
        snap = call(token) if record.snapshot is not None else None
        handed = Prepared(token.id, tuple(args))
        object.__setattr__(handed, "work", record.prepare(snap, *args))
        try:
            return call(handed)
        except Stale:
            continue
    who = f"{record.owner} {record.name}".strip()
    raise CommandError(f"{who}: refused: the motion queue kept changing while it was "
                       "planned; give it again; nothing moved")


def serve_prepared(record: Command, args: Sequence[Any], kept: dict[int, Any]) -> Any:
    """The loop's side of a prepared record (a station's ``execute``): a
    :class:`Snapshot` is taken and kept in ``kept``; a :class:`Prepared` goes to
    the handler (prepared here from the kept snapshot if it comes without its
    work: a replay); plain arguments are prepared here, in the calling thread."""
    if len(args) == 1 and isinstance(args[0], Snapshot):
        snap = record.snapshot() if record.snapshot is not None else None
        kept[args[0].id] = snap
        while len(kept) > KEPT_SNAPSHOTS:
            del kept[next(iter(kept))]
        return snap
    if len(args) == 1 and isinstance(args[0], Prepared):
        handed = args[0]
        snap = kept.pop(handed.id, None)
        work = handed.work
        if work is None:
            assert record.prepare is not None
            work = record.prepare(snap, *handed.args)
        return record.handler(work)
    return run_prepared(record, args, lambda arg: serve_prepared(record, [arg], kept))


def _signal_range(arg: Arg, obj: Any, owner: str) -> str:
    """The display range of ``obj``'s signal named like ``arg`` (a target ``x``
    beside the position signal ``x``) as help shows it, or ''.  Shown, not
    checked: the command's own checks say what is allowed inside it."""
    if arg.choices or arg.rest or arg.parse is str:
        return ""
    signal = getattr(obj, "signal", None)
    if not callable(signal):
        return ""
    try:
        s = signal(arg.name)
    except Exception:  # a component half built: no range to show
        return ""
    if not isinstance(s, Signal) or s.limits is None:
        return ""
    lim = s.limits
    units = f" {s.units}" if s.units else ""
    return f"{arg.name} {lim.lopr:g}..{lim.hopr:g}{units}"


def _bind_range(arg: Arg, obj: Any) -> Arg:
    """``arg`` with the range its owner holds now (``bounds``), else as it is."""
    if not arg.bounds:
        return arg
    lo, hi = getattr(obj, arg.bounds, (None, None)) or (None, None)
    return replace(arg, lo=lo, hi=hi)


# -- components ---------------------------------------------------------------------

#: The levels of a :class:`Message`, least urgent first.
MESSAGE_LEVELS = ("info", "warning", "error")
#: Messages a component holds before a station adopts it (the oldest go first).
HELD_MESSAGES = 256


@dataclass(frozen=True)
class Message:
    """Something a component says to the operator: who says it (``source``,
    the component's name), how urgent it is (``level``, one of
    :data:`MESSAGE_LEVELS`) and the ``text``, one line, complete in itself
    (a console shows the text as it is)."""

    source: str
    level: str
    text: str

    def __post_init__(self) -> None:
        if self.level not in MESSAGE_LEVELS:
            raise ValueError(f"message level must be one of {', '.join(MESSAGE_LEVELS)}, "
                             f"got {self.level!r}")

    def __str__(self) -> str:
        return self.text



@dataclass(frozen=True)
class Switch:
    """A handler's answer "the console's current level is now ``level``"."""

    level: Any
    lines: tuple[str, ...] = field(default=())


class Component:
    """The contract (see the module text).  Subclasses override what they have;
    the defaults are "none" (no signals, no children, nothing to stop)."""

    #: The name the console, the server and the scope address it by.
    name: str = ""
    #: A robot's joints for viewers (the root's): their URDF names, the signals
    #: giving each one's position (velocity, effort) and the URDF; ``scope foxglove``
    #: serves them as ``/joint_states``, ``pyrt export`` writes them.  None: no joints.
    joint_states: JointStates | None = None
    #: Where :meth:`fail` and :meth:`say` go: set by :meth:`connect`.
    _trip: Callable[[str, str], Any] | None = None
    _tell: Callable[[Message], None] | None = None
    _held: deque[Message] | None = None

    def signals(self) -> list[Signal]:
        """The component's signals."""
        return []

    def commands(self) -> list[Command]:
        """The component's command records (its methods marked with :func:`command`)."""
        return records_of(self, self.name)

    def children(self) -> list[Component]:
        """The components it is made of."""
        return []

    def params(self) -> list[Param]:
        """The component's run-time parameters (``get``/``set``); none by default."""
        return []

    def tasks(self) -> list[Task]:
        """The self-scheduling routines it runs on a ready queue (none by default)."""
        return []

    def reflex(self) -> None:
        """Stop every actuator of this component now (loop thread; must not raise)."""

    def enter_level(self) -> list[str]:
        """The console has made this component its command level (a handler
        returned :class:`Switch`); the lines to say (loop thread).  None by default."""
        return []

    def connect(self, *, trip: Callable[[str, str], Any] | None = None,
                tell: Callable[[Message], None] | None = None) -> None:
        """Send this component's faults to ``trip(cause, source)`` and its
        messages to ``tell(message)`` (a station's adopt does this for every
        component of its tree); the messages held so far go to ``tell`` now."""
        self._trip = trip
        self._tell = tell
        held = self._held
        if tell is not None and held:
            self._held = None
            for msg in held:
                tell(msg)

    def say(self, text: str, level: str = "info") -> None:
        """Tell the operator ``text`` (one line) at ``level``: a :class:`Message`
        from this component, published by its station (held until one adopts it)."""
        msg = Message(self.name, level, text)
        tell = self._tell
        if tell is not None:
            tell(msg)
            return
        if self._held is None:
            self._held = deque(maxlen=HELD_MESSAGES)
        self._held.append(msg)

    def held_messages(self) -> list[Message]:
        """The messages said before any station adopted this component (oldest first)."""
        return list(self._held or ())

    def fail(self, cause: str, source: str = "") -> None:
        """Report a fault of the robot.  Inside a station: the station records
        it and runs every component's reflex in this tick.  Before a station
        adopts it: the reflex of this component and of everything below it
        runs, and :class:`~pyrt.errors.FaultError` is raised to its builder."""
        trip = self._trip
        if trip is not None:
            trip(cause, source or self.name)
            return
        for c in reversed(list(walk(self))):  # leaves (motors) first, as a station does
            with contextlib.suppress(Exception):  # the failure raised below says why
                c.reflex()
        raise FaultError(Fault(robot=self.name, cause=cause, source=source or self.name))

    def signal(self, name: str) -> Signal | None:
        """The signal called ``name`` (case-insensitive), or None."""
        key = name.lower()
        for s in self.signals():
            if s.name.lower() == key:
                return s
        return None

    def run_command(self, name: str, *words: str) -> Any:
        """Run command ``name`` with ``words`` through its grammar (CommandError if
        unknown or malformed), in the calling thread."""
        rec = self.find_command(name)
        if rec is None:
            raise CommandError(f"{self.name}: unknown command {name[:40]!r}; expected one of "
                               f"{', '.join(c.name for c in self.commands()) or 'none'}")
        args = rec.parse(list(words), " ".join(words))
        if rec.prepare is not None:
            return serve_prepared(rec, args, {})
        return rec.handler(*args)

    def check_free(self, what: str) -> None:
        """Refuse a command that changes this device while its owner drives it
        (set ``owner_busy`` to a function returning the reason, or None)."""
        busy = getattr(self, "owner_busy", None)
        reason = busy() if busy is not None else None
        if reason:
            raise CommandError(f"{self.name} {what}: {reason}")

    def find_command(self, name: str) -> Command | None:
        """The command record called ``name`` (case-insensitive), or None."""
        if type(self).commands is Component.commands:  # the marked methods alone
            return record_named(self, name, self.name)
        for c in self.commands():
            if c.answers_to(name):
                return c
        return None


def walk(root: Component) -> Iterator[Component]:
    """``root`` and every component below it, depth first, each once."""
    seen: set[int] = set()
    stack = [root]
    while stack:
        c = stack.pop()
        if id(c) in seen:
            continue
        seen.add(id(c))
        yield c
        stack.extend(reversed(c.children()))
