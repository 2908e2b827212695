"""Start-up corrections of database values, bounded.

A start-up reconciles the databases with the world (000: POSITION must be
right before a start; an encoder's ZEROLENGTH is then set from the rope's
length there).  A small correction is the counter's rounding or a rope that
crept; a large one means a wrong entry (a slipped sign, a DEADLENGTH of 0, a
POSITION typed wrong), and acting on it would move every later target by
that much.  :func:`check_startup_correction` refuses a correction beyond
:data:`MAX_STARTUP_CORRECTION_CM` with one sentence naming both values and
how to confirm the new one (write it into the file).
"""

from __future__ import annotations

from typing import Any

__all__ = ["MAX_STARTUP_CORRECTION_CM", "check_startup_correction"]

#: The largest change a start-up makes to a length in a database on its own, cm.
MAX_STARTUP_CORRECTION_CM = 10.0


def check_startup_correction(record: Any, key: str, held: float, new: float, *,
                             what: str, check: str,
                             limit: float = MAX_STARTUP_CORRECTION_CM) -> None:
    """Refuse (:class:`~pyrt.errors.ConfigError` at ``record``'s ``key`` line) a
    start-up that would change ``key`` from ``held`` to ``new`` cm by more than
    ``limit``; ``what`` says where ``new`` comes from, ``check`` which entries to
    check first."""
    change = new - held
    if abs(change) <= limit:
        return
    kind = type(record).__name__.removesuffix("Record").upper()
    name = getattr(record, "name", "")
    raise record.where.error(key, (
        f"{kind} {name} {key} {held:.3f} cm: start-up would set it to {new:.3f} cm ({what}), "
        f"a change of {change:+.3f} cm, more than the {limit:g} cm a start-up corrects on its "
        f"own; nothing moved. Check {check}; if they are right, write {key}: {new:.3f} here "
        "to confirm it"))
