"""Replaying a journal in this process, as ``pyrt replay`` does, for the replay tests."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pyrt.journal import JournalReader
from pyrt.station.blackbox import with_snapshot
from pyrt.station.replay import Replay, ReplayResult


def replay_in_process(path: Path, tmp_path: Path) -> ReplayResult:
    """Replay the journal ``path`` on the station it names (built in a work folder of
    its own under ``tmp_path``) and return what the replay found."""
    from pyrt.cli.replay import build_replayed

    replay = Replay(path)
    work = tmp_path / f"work-{path.stem}"
    work.mkdir()
    station = build_replayed(replay, str(work))
    try:
        return replay.run()
    finally:
        replay.close()
        station.close()


def assert_each_snapshot_replays(pj: Path, taken: Sequence[Any], station: str,
                                 tmp_path: Path) -> None:
    """The journal ``pj`` resumed from each snapshot of ``taken`` (one black box a
    snapshot) replays identically from that snapshot's tick to the journal's end."""
    data = pj.read_bytes()
    last = JournalReader(pj).summary().last_tick
    for snap in taken:
        box = tmp_path / f"from-{snap.tick}.pj"
        box.write_bytes(with_snapshot(data, [snap], station))
        result = replay_in_process(box, tmp_path)
        assert result.identical, f"from tick {snap.tick}: {result.line()}"
        assert (result.first_tick, result.last_tick) == (snap.tick, last)
