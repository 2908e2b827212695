"""``pyrt export RUN.pj OUT.mcap``: a journal (a run's or a black box's) as an MCAP file.

MCAP is what ros2 bag writes by default; Foxglove, PlotJuggler and rerun open
it.  Every tick becomes a JSON message per board on ``/inputs/BOARD`` and
``/outputs/BOARD`` (the registers after the read and the write phase), one on
``/ticks`` (lateness, deadlines missed); each output written is a message on
``/writes`` (with the task that wrote it); requests, faults and other events
have ``/commands``, ``/faults`` and ``/events``.  Every channel has a JSON
schema; log times are the journal's tick times (the loop's clock, ns).  The
run's databases travel as attachments, its station and options as metadata.
For a station whose robot declares its joints (the example arm, and any whose
root component sets ``joint_states``), the journal is replayed (the station
must be installed) and the joints sampled every tick go on ``/joint_states``
as ``sensor_msgs/msg/JointState`` (SI units), with the URDF on
``/robot_description``: Foxglove's 3D panel plays the run back.
Needs the ``mcap`` library: ``pip install 'pyrt[mcap]'``.

A damaged journal (a checksum that does not match) is refused, naming the
frame and its offset; ``--salvage`` exports every tick it can read around
the damage, the ticks lost as messages on ``/gaps``.  A name that does not
end ``.mcap`` is a usage error (exit status 2, nothing read); a journal that
cannot be read, or a file that cannot be written, exit status 1 (and nothing
is written).
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

from pyrt.cli.replay import build_replayed
from pyrt.errors import CommandError, ConfigError
from pyrt.journal import JournalError, JournalReader
from pyrt.scope import MAX_BUFFER_BYTES, MAX_LENGTH
from pyrt.scope.mcapfile import JointSamples, export_journal, require_mcap
from pyrt.station.replay import Replay

__all__ = ["add_parser", "run"]


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("export", help="write a journal (--journal FILE, a black box) as "
                       "an MCAP file for Foxglove, PlotJuggler, rerun",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("journal", metavar="RUN.pj", help="a journal or a black box (.pj)")
    p.add_argument("out", metavar="OUT.mcap", help="the MCAP file to write")
    p.add_argument("--salvage", action="store_true",
                   help="read past damaged frames (the ticks lost go on /gaps)")
    p.set_defaults(run=run, usage=p.format_usage)


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if out.suffix.lower() != ".mcap":
        sys.stderr.write(args.usage())
        print(f"pyrt export: error: {args.out}: the output's name ends .mcap (the one format "
              "pyrt export writes)", file=sys.stderr)
        return 2
    if not out.parent.is_dir():
        sys.stderr.write(args.usage())
        print(f"pyrt export: error: {args.out}: there is no directory {out.parent}",
              file=sys.stderr)
        return 2
    try:
        require_mcap()
        reader = JournalReader(args.journal, salvage=args.salvage)
        joints, note = (None, "") if args.salvage else joint_samples(args.journal)
        done = export_journal(reader, out, joints)
    except (JournalError, CommandError) as exc:
        print(f"pyrt export: {exc}", file=sys.stderr)
        return 1
    print(f"pyrt export: {done.line()}", flush=True)
    if note:
        print(f"pyrt export: note: {note}", flush=True)
    return 0


def joint_samples(path: str | Path) -> tuple[JointSamples | None, str]:
    """The joints of the journal's station over its run, by a replay on virtual
    time: (None, "") for a station without joints; (None, why) when they
    cannot be had (the station is not installed, the replay differs ...)."""
    replay = Replay(path)
    tmp = tempfile.mkdtemp(prefix="pyrt-export-")
    station = None
    try:
        try:
            station = build_replayed(replay, tmp)
        except ConfigError as exc:
            return None, f"no /joint_states: the station cannot be built to replay ({exc})"
        joints = getattr(station.root, "joint_states", None)
        if joints is None:
            return None, ""
        names = joints.signals()
        scope = station.scope
        sources = [station.resolve_signal(n).scope_source() for n in names]
        for name, src in zip(names, sources, strict=True):
            scope.add(name, src)
        ticks = replay.reader.summary().ticks
        fits = MAX_BUFFER_BYTES // ((len(names) + 1) * 8) - 64
        scope.set_length(max(2, min(ticks, MAX_LENGTH, fits)))
        scope.run("roll")
        result = replay.run(None)
        scope.stop()
        frame = scope.read()
        if not result.identical:
            return None, f"no /joint_states: the replay differs ({result.line()})"
        if frame is None:
            return None, ""
        note = "" if frame.data.shape[0] == ticks else (
            f"/joint_states holds the last {frame.data.shape[0]} of {ticks} ticks")
        return JointSamples(joints, [s.units for s in sources], frame), note
    finally:
        replay.close()
        if station is not None:
            station.close()
        shutil.rmtree(tmp, ignore_errors=True)
