"""Start-up corrections of database values, bounded.

A start-up reconciles the databases with the world (000: POSITION must be
right before a start; an encoder's ZEROLENGTH is then set from the rope's
length there).  Where POSITION was moved (surveyed in, typed by hand), the
rope's LENGTH in AXIS.dat moves with it and accounts for the change.  What
it does not account for is a wrong entry: a DEADLENGTH of 0 (or a slipped
sign), a ZEROLENGTH typed by hand; acting on it would move every later
target by that much.  :func:`check_startup_correction` refuses a change
that POSITION does not explain by more than :data:`MAX_STARTUP_CORRECTION_CM`,
with one sentence naming both values and how to confirm the new one (write
it into the file).
"""

from __future__ import annotations

from typing import Any

__all__ = ["MAX_STARTUP_CORRECTION_CM", "check_startup_correction"]

#: The largest change of a database length that a start-up makes on its own,
#: beyond what the rope's length at POSITION explains, cm.
MAX_STARTUP_CORRECTION_CM = 10.0


def check_startup_correction(record: Any, key: str, held: float, new: float, *,
                             explained: float = 0.0, what: str, check: str,
                             limit: float = MAX_STARTUP_CORRECTION_CM) -> None:
    """Refuse (:class:`~pyrt.errors.ConfigError` at ``record``'s ``key`` line) a
    start-up that would change ``key`` from ``held`` to ``new`` cm by more than
    ``limit`` beyond ``explained`` (the change the rope's length at POSITION
    accounts for); ``what`` says where ``new`` comes from, ``check`` which
    entries to check first."""
    change = new - held
    if abs(change - explained) <= limit:
        return
    kind = type(record).__name__.removesuffix("Record").upper()
    name = getattr(record, "name", "")
    because = (f", of which POSITION explains {explained:+.3f} cm" if abs(explained) > limit
               else "")
    raise record.where.error(key, (
        f"{kind} {name} {key} {held:.3f} cm: start-up would set it to {new:.3f} cm ({what}), "
        f"a change of {change:+.3f} cm{because}, more than the {limit:g} cm a start-up "
        f"corrects on its own; nothing moved. Check {check}; if they are right, write "
        f"{key}: {new:.3f} here to confirm it"))
