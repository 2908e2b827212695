"""The recorder's hand-over of a tick: where it runs, and when it calls its tick listeners."""

from __future__ import annotations

from pyrt.journal import JournalReader
from pyrt.scheduler import Loop, SimClock
from pyrt.station.gripper import build_gripper
from pyrt.station.recording import Recorder


def _gripper():
    loop = Loop(SimClock(), period_ns=1_000_000)
    return loop, build_gripper(loop, boards="sim:")


def test_on_sim_the_tick_is_handed_over_at_the_end_of_the_write_phase(tmp_path):
    """On boards in this process the recorder needs no handler of its own: the image's
    write phase, the tick's last work, hands the tick over; closing the recorder
    detaches it, and every tick run is in the journal."""
    loop, station = _gripper()
    try:
        image = station.boards.image
        recorder = Recorder(station, tmp_path / "run.pj")
        assert recorder.in_write_phase
        assert "journal" not in loop.handler_names and loop.handler_names[-1] == "io:write"
        assert image.after_write is not None
        loop.run(ticks=25)
        recorder.close()
        assert image.after_write is None
        assert JournalReader(tmp_path / "run.pj").summary().ticks == 25
    finally:
        station.close()


def test_tick_listeners_are_called_at_the_ticks_they_ask_for(tmp_path):
    """The listeners are called at the earliest tick one of them asks for (every tick for
    one that asks for none); listen_at brings the next call forward."""
    loop, station = _gripper()
    try:
        recorder = Recorder(station, tmp_path / "run.pj")
        every, sparse = [], []

        def seldom(tick: int, _now: int) -> int:
            sparse.append(tick)
            return tick + 10

        recorder.tick_listeners.append(seldom)
        loop.run(ticks=25)
        assert sparse == [0, 10, 20]
        recorder.listen_at(loop.tick_index)  # at once, not at tick 30
        loop.run(ticks=1)
        assert sparse[-1] == 25
        recorder.tick_listeners.append(lambda tick, _now: every.append(tick))
        recorder.listen_at(loop.tick_index)
        loop.run(ticks=3)
        recorder.close()
        assert every == [26, 27, 28] and sparse[-3:] == every
    finally:
        station.close()


def test_outputs_written_by_a_disk_fault_s_reflex_are_stamped_journal(tmp_path):
    """A file of the recorder's that cannot be written trips the station at the recorder's
    next record (the end of the write phase): the outputs the reflex writes are the
    recorder's (``journal``), not the write phase's (``io:write``)."""
    import io

    from pyrt.commands import RobotShell

    _loop, station = _gripper()
    try:
        recorder = Recorder(station, tmp_path / "run.pj")
        station.start()
        shell = RobotShell(station, io.StringIO())
        for line in station.profile.startup_commands:
            shell.onecmd(line)
        shell.onecmd("P 30mm")
        station.runner.sleep(0.05)  # the jaws driven
        recorder.disk_fault("black box: disk full", "BLACKBOX")
        station.runner.sleep(0.01)
        recorder.close()
    finally:
        station.close()
    reader = JournalReader(tmp_path / "run.pj")
    (tripped,) = [t for t in reader.ticks() if any(e.name == "fault" for e in t.events)]
    writers = {reader.writers[w] for _slot, _value, w in tripped.outputs}
    assert writers == {"journal"}


def _recorded_run(path, *, in_c: bool) -> tuple[list, int, int]:
    """A gripper recorded on virtual time: idle, driven by commands, a deadline moved
    between runs, a listener added; the ticks read back, the ticks the recorder's own
    path took, and the ticks run.  ``in_c``: plain ticks handed over by the image's one
    C call (else every tick by the recorder's own path)."""
    import io

    from pyrt.commands import RobotShell

    loop, station = _gripper()
    try:
        image = station.boards.image
        recorder = Recorder(station, path)
        own = image.after_write
        calls = []

        def counted(now_ns: int, status: int) -> None:
            calls.append(loop.tick_index)
            own(now_ns, status)

        image.after_write = counted
        if not in_c:
            image.hand_over = None
        loop.run(ticks=300)  # idle
        station.start()
        shell = RobotShell(station, io.StringIO())
        for line in station.profile.startup_commands:
            shell.onecmd(line)
        shell.onecmd("P 30mm")
        station.runner.sleep(0.2)
        station.runner.stop()
        loop.resume_at(loop.now_ns, loop.deadline_ns + 7 * loop.period_ns)
        loop.run(ticks=50)
        seen: list[int] = []
        recorder.tick_listeners.append(lambda tick, _now: seen.append(tick) or tick + 20)
        loop.run(ticks=50)
        assert seen and seen[0] == loop.tick_index - 50 and seen[1] == seen[0] + 20
        image.after_write = own
        ran = loop.tick_index
        recorder.close()
    finally:
        station.close()
    ticks = [(t.tick, t.time_ns, t.lateness_ns, t.missed, t.inputs, t.outputs, t.commands,
              t.events) for t in JournalReader(path).ticks()]
    return ticks, len(calls), ran


def test_plain_ticks_are_handed_over_in_c_and_record_what_the_recorder_records(tmp_path):
    """Handed over by the write phase's one C call, a run's plain ticks are recorded as
    the recorder's own path records them (every tick, its clock, inputs, outputs,
    commands and events alike); that path runs only for the ticks that are not plain
    (outputs written, commands, a deadline moved, the listeners due)."""
    want, python_all, ran = _recorded_run(tmp_path / "python.pj", in_c=False)
    got, python_some, ran_c = _recorded_run(tmp_path / "c.pj", in_c=True)
    assert ran == ran_c and len(got) == ran
    assert got == want
    assert python_all == ran
    assert python_some < ran // 20, (python_some, ran)


def test_behind_a_handler_of_its_own_the_tick_is_handed_over_in_c_too(tmp_path):
    """When the write phase is not the tick's last work, the recorder's handler makes the
    one C call for a plain tick, and records every tick as its own path would."""
    runs = []
    for in_c in (True, False):
        loop, station = _gripper()
        try:
            loop.attach(lambda _now: None, name="after-io")
            recorder = Recorder(station, tmp_path / f"{in_c}.pj")
            assert not recorder.in_write_phase and "journal" in loop.handler_names
            if not in_c:
                recorder._hand_call = None
            own, slow = recorder._tick, []
            recorder._tick = lambda now, status, own=own, slow=slow: (  # type: ignore[method-assign]
                slow.append(now), own(now, status))
            loop.run(ticks=40)
            loop.resume_at(loop.now_ns, loop.deadline_ns + 3 * loop.period_ns)
            loop.run(ticks=40)
            handed = recorder.journal.recorded
            recorder.close()
        finally:
            station.close()
        ticks = [(t.tick, t.time_ns, t.lateness_ns, t.missed, t.inputs, t.outputs)
                 for t in JournalReader(tmp_path / f"{in_c}.pj").ticks()]
        assert len(ticks) == handed == 80
        assert len(slow) < 10 if in_c else len(slow) == 80
        runs.append(ticks)
    assert runs[0] == runs[1]


def _skip(loop, n: int) -> None:
    """``n`` deadlines skipped as an overrun at real time skips them: counted, and the
    next deadline ``n`` periods on."""
    loop.missed += n
    loop.overruns += 1
    loop.consecutive_overruns += 1
    loop.resume_at(loop.now_ns, loop.deadline_ns + n * loop.period_ns)


def test_a_statistics_reset_then_as_many_misses_as_before_is_recorded_exactly(tmp_path):
    """After a statistics reset, a skip that brings the count back to where it stood is
    recorded as the deadlines it skipped (not as no miss), the others as always."""
    loop, station = _gripper()
    try:
        recorder = Recorder(station, tmp_path / "run.pj")
        loop.run(ticks=5)
        _skip(loop, 2)
        loop.run(ticks=3)
        loop.reset_statistics()
        loop.run(ticks=3)
        _skip(loop, 2)  # the count back at 2
        loop.run(ticks=3)
        _skip(loop, 1)
        loop.run(ticks=2)
        recorder.close()
    finally:
        station.close()
    missed = [t.missed for t in JournalReader(tmp_path / "run.pj").ticks()]
    assert missed == [0] * 5 + [2, 0, 0] + [0] * 3 + [2, 0, 0] + [1, 0]
