"""Replaying a journal in this process, as ``pyrt replay`` does, for the replay tests."""

from __future__ import annotations

from pathlib import Path

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
