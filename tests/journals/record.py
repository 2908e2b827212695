"""Record the journals kept in tests/journals/ as regression cases (one per robot).

Each case is a real-time run (``--speed 1``, the default) of a robot's station
with ``--journal``, driven through its console: the script starts
``python -m pyrt ROBOT ... --journal FILE`` with its stdin on a pipe and
writes the case's lines one by one, sleeping between them as an operator
would type them.  Every case holds a move, an injected fault, the ``ack``
that clears the trip, and a ``stop``:

* ``gripper.pj``: ``P 30mm``; ``sim fault jam`` and a move that 002's stopped
  bit ends short; a schedule that makes MVJAWS drive with WATCHJAW's stale
  error (monitor ``C 45 18``), so that the next move oscillates and the move
  supervision trips; ``ack``; the schedule put back; a move and ``stop``.
* ``manipulator.pj`` (databases from ``--init-db`` in a temporary directory):
  ``prototype to 10 0 60``; ``sim fault axis0 slip 0.3`` and
  ``prototype to -20 0 40``, which trips "position estimate lost"; ``ack``;
  ``stop``.
* ``arm.pj`` (needs the arm: ``pip install -e ./examples/arm``): ``arm to 30
  60``; ``sim fault jam q0`` and a move that trips the following error;
  ``ack``; a move and ``stop``.

A journal is kept only if the run said what the case expects, the journal
replays identically (``pyrt replay``), holds the fault event and the ack, and
stays under :data:`MAX_BYTES`; otherwise the old file is left as it was and
the script exits 1.  The replays of these files are tests/test_journal_cases.py
and examples/arm/tests/test_journal_case.py.

When to re-record: whenever a deliberate change to a controller changes what
it writes (its outputs, the tick a fault trips, a fault's message) or the
journal's format, the kept journals no longer replay identically and the
tests say where ("replay differs at tick N ...").  Check that the
difference is the one intended, then re-record every case the change
touches, from the repository's root with pyrt (and the arm) installed::

    python tests/journals/record.py                  # every case
    python tests/journals/record.py gripper arm      # some of them

and commit the new journals with the change.  A run takes as long as its
moves do at real time (the manipulator about a minute); run it on a machine
that is not otherwise busy, since a run at real time records the ticks it
missed too (they replay just the same).
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parent
#: A kept journal must stay smaller than this.
MAX_BYTES = 200_000


@dataclass(frozen=True)
class Case:
    """One robot's run: the station's arguments and the console's lines."""

    name: str
    #: The station command's arguments (``{db}``: a temporary database directory).
    argv: tuple[str, ...]
    #: (line, seconds to sleep after writing it).
    lines: tuple[tuple[str, float], ...]
    #: What the console must have said (in this order).
    expect: tuple[str, ...]
    #: The fault's message (the event's message holds it, after the robot and tick).
    fault: str
    #: Text a move request holds.
    move: str
    #: A module the station needs (the case is skipped without it).
    needs: str = ""
    #: The station's exit status (a script run with -k whose fault failed a line: 1).
    status: int = 0


CASES: dict[str, Case] = {
    "gripper": Case(
        name="gripper",
        argv=("gripper",),
        lines=(
            ("P 30mm", 0.5), ("wait", 0.5),
            ("sim fault jam", 0.3), ("P 10mm", 0.3), ("wait", 0.5),
            ("sim fault none", 0.3),
            ("M", 0.2), ("C 45 18", 0.2), ("Q", 0.3),
            ("P 50mm", 0.3), ("wait", 0.5),
            ("ack", 0.3),
            ("M", 0.2), ("C 45 01", 0.2), ("Q", 0.3),
            ("P 30mm", 0.3), ("stop", 0.5),
            ("quit", 0.0),
        ),
        expect=("at target", "stopped short of the target", "the stopped bit ended the move",
                "P move oscillating about the target", "fault acknowledged",
                "every motor stopped"),
        fault="P move oscillating about the target",
        move='{"$r":"P"}',
    ),
    "manipulator": Case(
        name="manipulator",
        argv=("manipulator", "--init-db", "{db}"),
        lines=(
            ("prototype to 10 0 60", 0.5), ("wait", 0.5),
            ("sim fault axis0 slip 0.3", 0.3), ("prototype to -20 0 40", 0.5), ("wait", 0.5),
            ("ack", 0.3), ("stop", 0.5),
            ("quit", 0.0),
        ),
        expect=("ENDPOINT_STOP", "slip on axis0", "position estimate lost",
                "fault acknowledged", "every motor stopped"),
        fault="axis0: position estimate lost",
        move='{"$r":"to"}',
    ),
    "arm": Case(
        name="arm",
        argv=("arm", "-k"),
        lines=(
            ("arm to 30 60", 0.3), ("wait", 0.5),
            ("sim fault jam q0", 0.3), ("arm to 0 90", 0.3), ("wait", 0.5),
            ("sim fault none", 0.3), ("ack", 0.3),
            ("arm to 10 80", 0.3), ("stop", 0.5),
            ("quit", 0.0),
        ),
        expect=("at target", "q0 jammed", "FAULT: q0 following error", "fault acknowledged",
                "every motor stopped"),
        fault="q0 following error",
        move='{"$r":"to"}',
        needs="pyrt_arm",
        status=1,
    ),
}


def _pump(stream, sink: list[str]) -> None:
    for line in iter(stream.readline, ""):
        sink.append(line)
        sys.stdout.write("    | " + line)
        sys.stdout.flush()


def run_case(case: Case, journal: Path, work: Path) -> list[str]:
    """Run ``case`` at real time, recording into ``journal``; the console's lines."""
    db = work / "db"
    argv = [a.replace("{db}", str(db)) for a in case.argv]
    cmd = [sys.executable, "-m", "pyrt", *argv, "--speed", "1", "--journal", str(journal)]
    print(f"{case.name}: {' '.join(cmd[2:])}")
    # The working directory is the temporary one: a black box written on the
    # fault (at real time one is kept) lands there, not in the repository.
    proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, bufsize=1, cwd=work)
    assert proc.stdin is not None and proc.stdout is not None
    said: list[str] = []
    reader = threading.Thread(target=_pump, args=(proc.stdout, said), daemon=True)
    reader.start()
    time.sleep(1.0)  # the station starts (and the gripper runs I)
    for line, pause in case.lines:
        proc.stdin.write(line + "\n")
        proc.stdin.flush()
        time.sleep(pause)
    proc.stdin.close()
    rc = proc.wait(timeout=300)
    reader.join(timeout=5)
    if rc != case.status:
        raise SystemExit(f"{case.name}: the station exited with {rc}, not {case.status}")
    return said


def check_output(case: Case, said: list[str]) -> list[str]:
    """What the console should have said and did not (in order, in any case)."""
    text = "".join(said).lower()
    missing, at = [], 0
    for want in case.expect:
        k = text.find(want.lower(), at)
        if k < 0:
            missing.append(want)
        else:
            at = k + len(want)
    return missing


def check_journal(case: Case, path: Path) -> list[str]:
    """What the journal lacks: the problems found (none: it can be kept)."""
    from pyrt.journal import JournalReader

    problems = []
    size = path.stat().st_size
    if size >= MAX_BYTES:
        problems.append(f"{size} bytes (at most {MAX_BYTES})")
    reader = JournalReader(path)
    faults, commands, missed, late = [], [], 0, 0
    for t in reader:
        if not hasattr(t, "events"):
            problems.append(f"a gap: {t}")
            continue
        faults += [e.message for e in t.events if e.name == "fault"]
        commands += list(t.commands)
        missed += t.missed
        late = max(late, t.lateness_ns)
    if not any(case.fault in m for m in faults):
        problems.append(f"no fault event {case.fault!r} (faults: {faults})")
    for what, text, source in (("ack", "acknowledge", "ack"), ("move", case.move, ""),
                               ("stop", '"m":"stop"', "stop")):
        if not any(text in c.text and (not source or c.source == source) for c in commands):
            problems.append(f"no {what} request (text with {text!r})")
    s = reader.summary()
    print(f"{case.name}: " + "; ".join(s.lines())
          + f"; {missed} ticks missed, worst lateness {late / 1e6:.2f} ms")
    replay = subprocess.run([sys.executable, "-m", "pyrt", "replay", str(path)],
                            capture_output=True, text=True, timeout=300)
    print(f"{case.name}: " + replay.stdout.strip().replace("\n", "\n    "))
    if replay.returncode != 0 or "identical" not in replay.stdout:
        problems.append(f"the replay is not identical: {replay.stdout.strip()} "
                        f"{replay.stderr.strip()}")
    return problems


def record(case: Case) -> bool:
    """Record ``case`` and keep its journal if it passes every check."""
    if case.needs:
        try:
            __import__(case.needs)
        except ImportError:
            print(f"{case.name}: skipped: {case.needs} is not installed")
            return False
    work = Path(tempfile.mkdtemp(prefix=f"pyrt-record-{case.name}-"))
    try:
        journal = work / f"{case.name}.pj"
        said = run_case(case, journal, work)
        problems = [f"the console did not say {m!r}" for m in check_output(case, said)]
        if journal.exists():
            problems += check_journal(case, journal)
        else:
            problems.append("no journal was written")
        if problems:
            print(f"{case.name}: NOT kept:\n  " + "\n  ".join(problems))
            return False
        target = HERE / f"{case.name}.pj"
        shutil.copyfile(journal, target)
        print(f"{case.name}: kept {target} ({target.stat().st_size} bytes)")
        return True
    finally:
        shutil.rmtree(work, ignore_errors=True)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("cases", nargs="*", metavar="CASE",
                   help=f"which journals to record ({', '.join(CASES)}; default: all)")
    args = p.parse_args(argv)
    names = args.cases or list(CASES)
    unknown = [n for n in names if n not in CASES]
    if unknown:
        p.error(f"unknown case {unknown[0]!r}; choose from {', '.join(CASES)}")
    ok = [record(CASES[n]) for n in names]
    return 0 if all(ok) else 1


if __name__ == "__main__":
    sys.exit(main())
