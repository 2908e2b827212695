"""How a console line names what it runs: the part of
:class:`~pyrt.commands.RobotShell` that resolves a line to a word, an
object's command or a letter of the current level, and derives from the same
records what only reads, what anyone may give, and the completion table."""

from __future__ import annotations

import difflib
from typing import TYPE_CHECKING, Any

from pyrt.component import Command, Component, record_named, records_of
from pyrt.errors import CommandError

if TYPE_CHECKING:
    from pyrt.station.profile import ShellProfile

__all__ = ["LineResolver"]


class LineResolver:
    """Lines to records (see the module text); a part of ``RobotShell``."""

    if TYPE_CHECKING:  # the shell's, used here
        station: Any
        profile: ShellProfile
        level: Component | None
        _scope: Any

        @property
        def prompt(self) -> str: ...
        @property
        def in_monitor(self) -> bool: ...
        def _did_you_mean(self, text: str) -> str: ...
        def _channel_names(self) -> list[str]: ...

    # -- the records ------------------------------------------------------------------

    def words(self) -> list[Command]:
        """The shared words and the station's own words, as records."""
        own = records_of(self, "")
        extra = self.profile.words
        if extra is not None:
            own += extra.commands()
        return own

    def word(self, name: str) -> Command | None:
        """The word called ``name`` (case-insensitive), or None."""
        own = record_named(self, name, "")
        if own is not None:
            return own
        extra = self.profile.words
        return None if extra is None else next(
            (w for w in extra.commands() if w.answers_to(name)), None)

    def resolve(self, line: str) -> tuple[Component | None, Command, list[str], str]:
        """``(component, record, argument words, argument text)`` of ``line``
        (component None for a word); CommandError if it names nothing."""
        text = line.strip()
        words = text.split()
        if not words:
            raise CommandError("empty command")
        first = words[0]
        if len(first) > 1:
            w = self.word(first)
            if w is not None:
                # the shell's own words run here; a station's words (the
                # manipulator's log, debug) in the loop like any command
                owner = self.profile.words
                mine = owner is None or owner.find_command(first) is None
                return (None if mine else owner), w, words[1:], text[len(first):].strip()
            comp = self.station.find(first)
            if comp is not None:
                return self._object(comp, words, text)
        level = self.level
        if level is not None and first[0].isalpha():
            shown = self.prompt.strip().rstrip(":*").strip()
            if shown and len(first) > 1 and first.rstrip(":").lower() == shown.lower():
                letters = " ".join(c.name for c in level.commands())
                raise CommandError(f"{first[:40]!r} is the prompt, not a command: type a "
                                   f"letter after it ({letters}), or help")
            rec = level.find_command(first[0])
            if rec is not None:
                rest = text[1:].strip()
                return level, rec, rest.split(), rest
            letters = " ".join(c.name for c in level.commands())
            where = "monitor command" if self.in_monitor else "command"
            raise CommandError(f"unknown {where} {first[:40]!r} (letters: {letters}; "
                               "words: type help)")
        raise CommandError(f"unknown command or object {first[:40]!r}"
                           f"{self._did_you_mean(first)}; objects: "
                           f"{', '.join(self.station.names())}; type help")

    def _object(self, comp: Component, words: list[str], text: str
                ) -> tuple[Component | None, Command, list[str], str]:
        if len(words) < 2:  # an object alone shows itself, or reads its signals
            show = comp.find_command("show")
            if show is not None and not show.args:
                return comp, show, [], ""
            status = self.word("status")
            assert status is not None
            return None, status, [comp.name], comp.name
        rec = comp.find_command(words[1])
        if rec is None:
            verbs = [n for c in comp.commands() for n in (c.name, *c.aliases)]
            raise CommandError(f"{comp.name}: unknown command {words[1][:40]!r}"
                               f"{_did_you_mean(words[1], verbs)}; expected one "
                               f"of {', '.join(c.name for c in comp.commands()) or 'none'}")
        rest = text[len(words[0]):].strip()[len(words[1]):].strip()
        return comp, rec, words[2:], rest

    def reads_only(self, line: str) -> bool:
        """True when ``line`` only reads (the server serves it without privilege)."""
        try:
            _comp, rec, words, _rest = self.resolve(line)
        except CommandError:
            return False
        return rec.only_reads(words)

    def anyone(self, line: str) -> bool:
        """True when any client may give ``line`` (it reads, or it is the stop)."""
        try:
            _comp, rec, words, _rest = self.resolve(line)
        except CommandError:
            return False
        return rec.anyone or rec.only_reads(words)

    def completions(self) -> dict[str, Any]:
        """The nested completion table: words, then objects and their verbs
        (each record's name and its aliases: every name the object answers to)."""
        table: dict[str, Any] = {w.name: None for w in self.words()}
        if self.level is not None:  # the letters typed bare at this level's prompt
            for c in self.level.commands():
                table.setdefault(c.name, None)
        for comp in self.station.components():
            if comp is self.profile.words:
                continue  # its records are words, above
            verbs: dict[str, Any] = {}
            for c in comp.commands():
                verbs[c.name] = None
                verbs.update(dict.fromkeys(c.aliases))
            table[comp.name] = verbs or None
        objects = {name: None for name in table if name not in ("help",)}
        table["help"] = objects
        table["status"] = {c.name: None for c in self.station.components()
                           if c.signals()} or None
        channels: dict[str, Any] = {}
        names = self._channel_names() + [n for n, _ in self.station.signals()]
        channels.update({name: channels for name in names if name != "ram:XX"})
        subs: dict[str, Any] = {verb: None for verb in self._scope.verbs()}
        subs.update(add=channels, trigger={name: None for name in channels})
        table["scope"] = subs
        table["motion"] = dict.fromkeys(self.station.motion_types())
        return table


def _did_you_mean(text: str, names: list[str]) -> str:
    """``" (did you mean 'NAME'?)"`` for the names closest to ``text`` (difflib), or
    '' (never ``text`` itself: ``quit now`` is quit given an argument, not a misspelling)."""
    by_key = {n.lower(): n for n in names if n.lower() != text.lower()}
    near = difflib.get_close_matches(text.lower(), list(by_key), n=2, cutoff=0.7)
    if not near:
        return ""
    return f" (did you mean {' or '.join(repr(by_key[k]) for k in near)}?)"


