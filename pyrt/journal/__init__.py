"""The flight recorder: a journal of a run's inputs, clock decisions and outputs.

:class:`Journal` records (a thread encodes and writes; the loop thread only
hands each tick over), :class:`JournalReader` reads back, :class:`BlackBox`
keeps the last seconds in memory.  The file format is specified in
:mod:`pyrt.journal.format`.  This package stands beside the scheduler: it
imports nothing of pyrt but the errors, the version and the C kernels'
wrappers (the tick records are encoded in C, :mod:`pyrt.journal.encoder`).

How a station uses it (once per run; ``inputs``: the process image in, in
declared order; ``writes``: the changed outputs of the tick with the index of
the task that wrote each)::

    header = Header(station="gripper", period_ns=loop.period_ns,
                    inputs=image_input_names, outputs=image_output_names,
                    version=pyrt.__version__, databases={"gripper.dat": raw_bytes},
                    seeds={"plant": 1234}, writers=task_names)
    journal = Journal(header, "run.pj", black_box=BlackBox(seconds=10),
                      lossless=loop.clock.virtual)
    # in the loop thread, at the end of every tick:
    journal.record_tick(tick, now_ns, lateness_ns, missed, inputs, writes,
                        commands=[(text, source)], events=[("fault", id, message)])
    # on a fault (any thread; written by the journal's thread):
    journal.dump_black_box("gripper-fault-3.pj")
    journal.close()

    reader = JournalReader("run.pj")          # salvage=True to read past damage
    for record in reader:                      # Tick and Gap records
        ...
    reader.seek(120_000); reader.summary().lines()
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
