"""What the console of a station looks like: :class:`ShellProfile`.

A station is a lifecycle; how its console reads is presentation, and it is
stated here, once, by the module that assembles the station (its factory's
build): the prompt (one per command level), the component whose commands
are single letters at the prompt (the gripper's ``CMD:``), a component whose
commands are console words (the manipulator's ``log`` and ``debug``), the
lines run before the operator types (the gripper's power-up ``I``), and how
``wait`` words an idle robot and a fault.  The shell
(:class:`~pyrt.commands.RobotShell`), the server's shells and the reference
read it from ``station.profile``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

__all__ = ["ShellProfile"]


@dataclass(frozen=True)
class ShellProfile:
    """How a station's console reads (see the module text)."""

    #: The prompt at the top level ('' : ``NAME> ``).
    prompt: str = ""
    #: The component whose commands are single letters at the prompt, or None:
    #: commands are ``OBJECT VERB``.
    level: Any = None
    #: The prompt at each command level, by the level component's name.
    level_prompts: Mapping[str, str] = field(default_factory=dict)
    #: A component whose commands are console words of this station, or None.
    words: Any = None
    #: Console lines run once the loop runs, before the operator types.
    startup_commands: tuple[str, ...] = ()
    #: How ``wait`` opens the line of a fault that ended the move it waited for.
    fault_prefix: str = "FAULT"
    #: What ``wait`` says with nothing to wait for: ``{where}`` is where the
    #: robot is, ``{last}`` "; last stop: REASON" after a move ('' before).
    idle: str = "nothing to wait for{last}"
    #: The console says how each move ended as it happens (between waits).
    announce_stops: bool = False

    def prompt_at(self, name: str, level: Any) -> str:
        """The prompt of station ``name`` at command level ``level``."""
        if level is not None:
            text = self.level_prompts.get(getattr(level, "name", ""))
            if text is not None:
                return text
        return self.prompt or f"{name}> "

    def idle_line(self, where: str, last: str) -> str:
        """``wait``'s line when nothing runs (``last``: the last move's reason, or '')."""
        return self.idle.format(where=where, last=f"; last stop: {last}" if last else "")
