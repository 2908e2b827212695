"""One fault path: every cause reaches Station.trip, which publishes the first fault once,
as one event with an id; the console, a DAQ subscriber and EPICS each show it once."""

from __future__ import annotations

import io

import pytest
from test_epics import PREFIX, _text, _until, epics_env, epics_served  # noqa: F401

from pyrt.commands import RobotShell
from pyrt.errors import FaultError
from pyrt.scheduler import Loop, SimClock
from pyrt.station.gripper import build_gripper

#: Only a hang takes this long: a bound that catches one, never a measure of speed.
HANG_S = 30.0


def test_fault_ids_count_up_and_a_later_cause_is_not_published_again():
    """The first trip is the station's fault (id 1); a second cause while stopped runs the
    reflex again but publishes nothing; after ack the next fault is id 2."""
    station = build_gripper(Loop(SimClock()))
    runner = station.start()
    published = []
    station.loop.fault_listeners.append(published.append)
    try:
        first = runner.call(station.controller.fail, "first cause", take_fault=False)
        assert first is None
        again = runner.call(station.trip, "second cause", "test", take_fault=False)
        assert [f.cause for f in published] == ["first cause"] and published[0].id >= 1
        assert again is published[0] and station.fault is published[0]
        with pytest.raises(FaultError) as info:
            runner.call(station.status)
        assert info.value.fault is published[0]
        runner.call(station.acknowledge)
        runner.call(station.trip, "third cause", "test", take_fault=False)
        assert [f.id for f in published] == [published[0].id, published[0].id + 1]
    finally:
        station.close()


def test_the_shell_shows_each_fault_event_once():
    """A fault seen in the console's asynchronous lines is not raised again by the next
    command, and a command that meets it first shows it once."""
    station = build_gripper(Loop(SimClock()))
    runner = station.start()
    out = io.StringIO()
    shell = RobotShell(station, out)
    try:
        runner.call(station.controller.fail, "seen as a message", take_fault=False)
        lines = shell.messages()
        assert sum(ln.startswith("FAULT") and "seen as a message" in ln for ln in lines) == 1
        shell.onecmd("S")
        assert not any(ln.startswith("FAULT") for ln in out.getvalue().splitlines())
        shell.onecmd("ack")
        runner.call(station.controller.fail, "met by a command", take_fault=False)
        shell.onecmd("S")
        shell.onecmd("T")
        shown = [ln for ln in out.getvalue().splitlines() if ln.startswith("FAULT")]
        assert len(shown) == 1 and "met by a command" in shown[0], out.getvalue()
        assert not any(ln.startswith("FAULT") for ln in shell.messages())
    finally:
        station.close()


def test_a_fault_during_a_move_is_shown_once_on_console_daq_and_epics(epics_env):  # noqa: F811
    """A fault raised during a P move (and a second cause while stopped) is shown once in the
    console, once on a subscribed DAQ client and written once to EPICS FAULT_MSG."""
    with epics_served() as (sv, ioc):
        pv = ioc.pvdb[PREFIX + "FAULT_MSG"]
        writes: list[str] = []
        original = pv.write

        async def counting(value, *args, **kwargs):
            writes.append(str(value))
            return await original(value, *args, **kwargs)

        pv.write = counting
        daq = sv.client(timeout_s=HANG_S)
        stream = daq.subscribe(200, timeout_s=HANG_S)
        out = io.StringIO()
        shell = RobotShell(sv.rig, out)
        shell.onecmd("I")
        shell.onecmd("P E47A")
        sv.runner.sleep(0.3)
        assert sv.runner.call(lambda: sv.rig.controller.moving, take_fault=False)
        sv.runner.call(sv.rig.controller.fail, "jaw drive lost (test)", take_fault=False)
        sv.runner.call(sv.rig.trip, "a second cause while stopped", "test", take_fault=False)
        t_trips = sv.runner.call(lambda: sv.rig.loop.now_ns, take_fault=False) / 1e9
        sv.runner.sleep(0.3)
        console = "\n".join(shell.messages())
        shell.onecmd("status")
        shell.onecmd("wait")
        console += "\n" + out.getvalue()
        shown = [ln for ln in console.splitlines() if ln.startswith("FAULT")]
        assert len(shown) == 1 and "jaw drive lost (test)" in shown[0], console
        assert "a second cause" not in console
        # The stream is in order: once a sample from 0.1 s after both trips has come, every
        # fault event they published has come before it.
        faults = []
        for status in stream:
            if status.fault is not None:
                faults.append(status.fault)
            elif status.time_s is not None and status.time_s > t_trips + 0.1:
                break
        else:
            raise AssertionError(f"the stream ended before a sample after the trips: {faults}")
        assert len(faults) == 1 and "jaw drive lost (test)" in faults[0], faults
        assert _until(lambda: _text("FAULT_MSG") == "jaw drive lost (test)", HANG_S)
        # Two more samples reach T, each in a later pass of the IOC: the first pass ran its
        # fault check whole after FAULT_MSG was written, and wrote nothing more.
        for _ in range(2):
            sv.runner.sleep(0.05)
            t = sv.runner.call(lambda: sv.rig.loop.now_ns, take_fault=False) / 1e9
            assert _until(lambda t=t: ioc.pvdb[PREFIX + "T"].value >= t - 1e-9, HANG_S)
        assert writes == ["jaw drive lost (test)"], writes
        daq.close()
