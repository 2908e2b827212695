"""The flight recorder: a journal of a run's inputs, clock decisions and outputs.

:class:`Journal` records (a thread encodes and writes; the loop thread only
hands each tick over), :class:`JournalReader` reads back, :class:`BlackBox`
keeps the last seconds in memory.  The file format is specified in
:mod:`pyrt.journal.format`.  This package stands beside the scheduler: it
imports nothing of pyrt but the errors and the version.
"""

from pyrt.journal.format import FORMAT, Command, Event, Gap, Header, JournalError, Tick
from pyrt.journal.reader import Damage, JournalReader, Summary, read_journal
from pyrt.journal.ring import DEFAULT_BUDGET, DEFAULT_SECONDS, BlackBox
from pyrt.journal.writer import DEFAULT_BLOCK_TICKS, DEFAULT_QUEUE_TICKS, Journal

__all__ = [
    "DEFAULT_BLOCK_TICKS",
    "DEFAULT_BUDGET",
    "DEFAULT_QUEUE_TICKS",
    "DEFAULT_SECONDS",
    "FORMAT",
    "BlackBox",
    "Command",
    "Damage",
    "Event",
    "Gap",
    "Header",
    "Journal",
    "JournalError",
    "JournalReader",
    "Summary",
    "Tick",
    "read_journal",
]
