"""The software oscilloscope: sources, triggers with pre/post samples, modes, export, spew."""

from __future__ import annotations

import csv
import itertools

import numpy as np
import pytest

from pyrt.errors import CommandError
from pyrt.scheduler import Loop, SimClock
from pyrt.scope import Scope, Source, Spew, compile_sources, plot_frame, save_frame


class Signal:
    """A synthetic plant: a ramp that counts ticks, and a square wave."""

    def __init__(self):
        self.n = 0
        self.ramp = 0.0
        self.square = 0.0

    def step(self, now_ns: int) -> None:
        self.n += 1
        self.ramp = float(self.n)
        self.square = 1.0 if (self.n // 50) % 2 else 0.0


def rig(capacity=100, every=1):
    loop = Loop(SimClock())
    sig = Signal()
    scope = Scope(capacity=capacity, every=every)
    loop.attach(sig.step)
    loop.attach(scope.sample)
    scope.add("ramp", Source.attr(sig, "ramp"))
    scope.add("square", Source.attr(sig, "square"))
    return loop, sig, scope


def test_compiled_sources_read_attributes_items_words_and_calls():
    """One compiled getter reads an attribute, an item, a signed RAM word and a call."""
    class Obj:
        x = 2.5

    ram = bytearray(128)
    ram[0x4A], ram[0x4B] = 0x7A, 0xE4  # E47A = -1B86
    read = compile_sources([
        Source.attr(Obj(), "x"), Source.item([7, 8, 9], 1),
        Source.word(ram, 0x4A, signed=True), Source.word(ram, 0x4A), Source.call(lambda: 4),
    ])
    assert read() == (2.5, 8, -0x1B86, 0xE47A, 4)


def test_bad_sources_are_refused():
    """Unknown attributes, bad names, out-of-range words and indices are refused when the channel is made."""
    with pytest.raises(ValueError):
        Source.attr(object(), "nope")
    with pytest.raises(ValueError):
        Source.attr(object(), "__class__; import os")
    with pytest.raises(ValueError):
        Source.word(bytearray(128), 0x7F)
    with pytest.raises(ValueError):
        Source.item([1], 3)


def test_rising_trigger_captures_the_right_pre_and_post_samples():
    """A rising trigger at level 0.5 on the square wave: 10% pre-trigger, the edge at index 10."""
    loop, _sig, scope = rig(capacity=100)
    scope.set_trigger("square", 0.5, "rising", pre=0.1)
    scope.run("single")
    loop.run(400)
    frame = scope.read()
    assert frame is not None and frame.trigger_index == 10
    ramp = frame.column("ramp")
    # The square wave first rises at tick 50; the frame holds ticks 40..139.
    assert ramp[0] == 40 and ramp[10] == 50 and ramp[-1] == 139
    assert frame.column("square")[9] == 0.0 and frame.column("square")[10] == 1.0
    assert np.all(np.diff(frame.t_ns) == 1_000_000)
    assert scope.state == "done" and scope.frames == 1


def test_falling_trigger_and_normal_mode_rearms():
    """Normal mode captures a frame at each falling edge and keeps the latest."""
    loop, _, scope = rig(capacity=60)
    scope.set_trigger("square", 0.5, "falling", pre=0.5)
    scope.run("normal")
    loop.run(1000)
    frame = scope.read()
    # Falling edges at ticks 100, 200, ... 1000; the one at 1000 is still capturing.
    assert scope.frames == 9 and scope.state == "triggered"
    assert frame.trigger_index == 30 and frame.column("ramp")[frame.trigger_index] == 900
    assert frame.column("square")[frame.trigger_index - 1] == 1.0


def test_trigger_needs_full_pre_trigger_history():
    """An edge before the pre-trigger part has filled is ignored; the next one triggers."""
    loop, _, scope = rig(capacity=100)
    scope.set_trigger("square", 0.5, "rising", pre=0.9)  # needs 90 samples first
    scope.run("single")
    loop.run(400)
    frame = scope.read()
    assert frame.column("ramp")[frame.trigger_index] == 150


def test_auto_mode_captures_without_a_trigger():
    """Auto mode with no trigger event captures one frame per frame length anyway."""
    loop, _, scope = rig(capacity=100)
    scope.run("auto")
    loop.run(250)
    frame = scope.read()
    # The forced frame is the latest 100 samples when the wait runs out; the
    # check is made as samples are folded in (every 64), so the frame's end
    # is the latest folded sample.
    assert scope.frames == 2 and frame.trigger_index is None
    ramp = frame.column("ramp")
    assert ramp.size == 100 and np.all(np.diff(ramp) == 1) and ramp[-1] == 250


def test_roll_mode_keeps_the_latest_samples():
    """Roll mode: the read-out is the latest capacity samples, oldest first."""
    loop, _, scope = rig(capacity=100, every=2)
    scope.run("roll")
    loop.run(1000)
    frame = scope.read()
    assert frame.data.shape == (100, 2)
    assert frame.column("ramp")[-1] == 1000 and frame.column("ramp")[0] == 802


def test_sixteen_channels_and_sixteen_thousand_samples():
    """The scope holds at least 16 channels of 16,000 samples."""
    loop = Loop(SimClock())
    sig = Signal()
    loop.attach(sig.step)
    scope = Scope()
    loop.attach(scope.sample)
    for k in range(16):
        scope.add(f"c{k}", Source.attr(sig, "ramp"))
    scope.run("roll")
    loop.run(16_100)
    frame = scope.read()
    assert frame.data.shape == (16_000, 16) and frame.data[-1, 15] == 16_100
    with pytest.raises(CommandError):
        scope.add("c16", Source.attr(sig, "ramp"))


def test_bad_scope_commands_are_refused():
    """Unknown modes, missing triggers, duplicate channels and bad pre fractions give CommandError."""
    _, sig, scope = rig()
    with pytest.raises(CommandError, match="needs a trigger"):
        scope.run("normal")
    with pytest.raises(CommandError):
        scope.run("sideways")
    with pytest.raises(CommandError):
        scope.add("ramp", Source.attr(sig, "ramp"))
    with pytest.raises(CommandError):
        scope.set_trigger("nope", 1.0)
    with pytest.raises(CommandError):
        scope.set_trigger("ramp", 1.0, pre=1.5)
    with pytest.raises(CommandError):
        scope.set_trigger("ramp", 1.0, edge="sideways")
    assert Scope().read() is None


def test_export_csv_and_npz(tmp_path):
    """A frame saves as CSV with a header naming the columns, and as .npz; other suffixes are refused."""
    loop, _, scope = rig(capacity=50)
    scope.run("roll")
    loop.run(60)
    frame = scope.read()
    path = save_frame(frame, tmp_path / "f.csv")
    rows = list(csv.reader(path.open()))
    assert rows[0] == ["t_s", "ramp", "square"] and len(rows) == 51
    assert float(rows[1][1]) == 11.0 and float(rows[1][0]) == pytest.approx(0.011)
    npz = np.load(save_frame(frame, tmp_path / "f.npz"))
    assert list(npz["channels"]) == ["ramp", "square"] and npz["data"].shape == (50, 2)
    with pytest.raises(CommandError, match=r"\.csv, \.npz or \.mcap"):
        save_frame(frame, tmp_path / "f.txt")


def test_plot_writes_a_png(tmp_path):
    """scope plot draws the frame to PNG."""
    pytest.importorskip("matplotlib")
    loop, _, scope = rig(capacity=50)
    scope.set_trigger("square", 0.5)
    scope.run("single")
    loop.run(200)
    path = plot_frame(scope.read(), tmp_path / "f.png")
    assert path.read_bytes()[:4] == b"\x89PNG"


def test_spew_hands_values_at_a_fixed_rate():
    """Spew calls its subscriber every 1/hz of loop time, never in bursts."""
    loop = Loop(SimClock())
    sig = Signal()
    loop.attach(sig.step)
    got = []
    spew = Spew(["ramp"], [Source.attr(sig, "ramp")], 100.0, lambda t, v: got.append((t, v)))
    loop.attach(spew)
    loop.run(1000)
    assert len(got) == 100
    assert all(b[0] - a[0] == 10_000_000 for a, b in itertools.pairwise(got))
    assert got[0][1] == (1.0,)


def test_a_channel_that_stops_reading_as_a_number_stops_the_scope_not_the_loop():
    """If a channel's value turns into something that is not a number, the scope stops with a reason."""
    loop, sig, scope = rig(capacity=100)
    sig.extra = 1.0
    scope.add("extra", Source.attr(sig, "extra"))
    scope.run("roll")
    loop.run(10)
    sig.extra = None
    loop.run(10)
    assert scope.state == "stopped" and "sampling stopped" in scope.status()
    assert scope.read().data.shape == (10, 3)


def test_run_without_a_mode_or_trigger_chooses_auto():
    """'scope run' alone on a fresh scope acquires (auto mode) instead of asking for a trigger."""
    loop, _, scope = rig(capacity=100)
    scope.run()
    assert scope.mode == "auto" and scope.state == "armed"
    loop.run(250)
    assert scope.read().data.shape == (100, 2)


@pytest.mark.parametrize("ticks", [1, 37, 99])
def test_stop_before_the_first_frame_keeps_what_was_sampled(ticks):
    """Auto mode stopped before a frame filled: the samples taken so far (shown as they
    came) are the frame."""
    loop, _, scope = rig(capacity=100)
    scope.run("auto")
    loop.run(ticks)
    assert scope.read().data.shape == (ticks, 2)
    scope.stop()
    frame = scope.read()
    assert frame is not None and frame.data.shape == (ticks, 2)
    assert list(frame.data[:, 0]) == [float(n) for n in range(1, ticks + 1)]


def test_stop_after_a_trigger_keeps_the_partial_frame_with_its_trigger():
    """Stopped after the trigger but before the post-trigger samples: the frame keeps the trigger."""
    loop, _, scope = rig(capacity=100)
    scope.set_trigger("square", 0.5, "rising", pre=0.2)
    scope.run("normal")
    loop.run(60)  # the square rises at tick 50; 80 post-trigger samples are not there yet
    scope.stop()
    frame = scope.read()
    assert frame.trigger_index is not None
    assert frame.data[frame.trigger_index, 1] == 1.0 and frame.data[frame.trigger_index - 1, 1] == 0.0


def test_the_pre_trigger_fill_is_shown_and_a_single_armed_before_it_captures_the_next_event():
    """Single, pre 0.9: the fill is shown as it grows; the rising edge at tick 50 (during the fill) is counted, not taken; the edge at 150 makes the frame."""
    loop, _, scope = rig(capacity=100)
    scope.set_trigger("square", 0.5, "rising", pre=0.9)  # 90 samples to fill
    scope.run("single")
    loop.run(36)
    assert scope.pre_fill() == pytest.approx(0.4)
    assert "armed (single), pre-trigger 40 % filled (the trigger arms when it is full)" \
        in scope.status()
    loop.run(64)  # tick 100: the fill is full; the edge at 50 came during it
    assert scope.pre_fill() == 1.0 and "pre-trigger full" in scope.status()
    assert scope.missed == 1 and scope.missed_t_ns == 50 * 1_000_000
    assert "1 trigger event came while the pre-trigger part filled and was not taken" \
        in scope.waiting()
    loop.run(300)
    frame = scope.read()
    assert scope.state == "done" and scope.frames == 1
    assert frame.column("ramp")[frame.trigger_index] == 150 and frame.trigger_index == 90
    scope.run("single")  # arming again forgets what the last fill missed
    assert scope.missed == 0 and scope.missed_note() == ""


def test_normal_mode_counts_the_events_each_refill_misses():
    """Normal mode fills again after each frame: the edges of each fill are counted, the first edge after it triggers."""
    loop, _, scope = rig(capacity=200)
    scope.set_trigger("square", 0.5, "rising", pre=0.9)  # 180 samples to fill; edges 100 apart
    scope.run("normal")
    loop.run(1000)
    # the first fill (ticks 1..180) misses 50 and 150; the frame at 250 ends at 269,
    # the refill (270..449) misses 350, and 450 is the first edge after it; and so on
    assert scope.frames == 4 and scope.missed == 6 and scope.missed_t_ns == 950_000_000
    frame = scope.read()
    assert frame.column("square")[frame.trigger_index - 1] == 0.0
    assert frame.column("square")[frame.trigger_index] == 1.0


def test_record_length_is_bounded_by_count_and_memory():
    """set_length takes 2..1,000,000 samples within the 64 MiB buffer bound; a refusal changes nothing."""
    from pyrt.scope.scope import MAX_BUFFER_BYTES, buffer_bytes

    loop, sig, scope = rig(capacity=100)
    scope.set_length(500)
    assert scope.capacity == 500
    scope.run("roll")
    loop.run(600)
    assert scope.read().data.shape == (500, 2)
    for bad in (1, 0, 1_000_001, 2.5, True):
        with pytest.raises(CommandError, match="record length"):
            scope.set_length(bad)
    for k in range(14):
        scope.add(f"c{k}", Source.attr(sig, "ramp"))
    assert buffer_bytes(1_000_000, 16) > MAX_BUFFER_BYTES
    with pytest.raises(CommandError, match="MiB"):
        scope.set_length(1_000_000)
    assert scope.capacity == 500


def test_csv_header_carries_each_channels_units(tmp_path):
    """The CSV header names each column with its units (encoder [counts]); a channel without units keeps its name alone."""
    loop = Loop(SimClock())
    sig = Signal()
    loop.attach(sig.step)
    scope = Scope(capacity=20)
    loop.attach(scope.sample)
    scope.add("encoder", Source.attr(sig, "ramp").described("counts"))
    scope.add("square", Source.attr(sig, "square"))
    scope.run("roll")
    loop.run(30)
    rows = list(csv.reader(save_frame(scope.read(), tmp_path / "f.csv").open()))
    assert rows[0] == ["t_s", "encoder [counts]", "square"]
    assert list(np.load(save_frame(scope.read(), tmp_path / "f.npz"))["units"]) == ["counts", ""]


# -- samples show as they come -----------------------------------------------------------------


@pytest.mark.parametrize("ticks", [1, 63, 64, 65, 99, 100, 101, 250])
def test_the_default_scope_shows_the_samples_as_they_come(ticks):
    """'scope run' on a fresh scope (auto, no trigger) shows every sample up to now, the
    latest frame length of them, before any frame has filled and after."""
    loop, _, scope = rig(capacity=100)
    scope.run()
    loop.run(ticks)
    ramp = scope.read().column("ramp")
    assert list(ramp) == [float(n) for n in range(max(1, ticks - 99), ticks + 1)]
    scope.stop()  # what was shown is what is kept
    assert list(scope.read().column("ramp")) == list(ramp)


def test_a_triggered_frame_shows_as_it_fills():
    """After the trigger, before the frame is full, read gives the frame so far with its
    trigger point; a normal scope before its trigger shows nothing."""
    loop, _, scope = rig(capacity=100)
    scope.set_trigger("square", 0.5, "rising", pre=0.2)
    scope.run("normal")
    loop.run(40)
    assert scope.read() is None
    loop.run(30)  # the square rises at tick 50: 20 samples of the 80 after it are there
    frame = scope.read()
    assert frame.trigger_index == 20 and frame.data.shape == (41, 2)
    assert frame.column("ramp")[frame.trigger_index] == 50 and frame.column("ramp")[-1] == 70
    assert scope.frames == 0 and scope.state == "triggered"


def test_auto_with_a_trigger_shows_the_samples_while_it_waits():
    """Auto mode waiting for its trigger shows the samples since it was armed."""
    loop, _, scope = rig(capacity=100)
    scope.set_trigger("ramp", 1e9)  # never comes
    scope.run("auto")
    loop.run(30)
    assert list(scope.read().column("ramp")) == [float(n) for n in range(1, 31)]


# -- closing the live sinks with the station ------------------------------------------------


def _wait_refused(port: int) -> bool:
    """True once nothing accepts a TCP connection on loopback ``port``; polled, bounded by
    10 s (only a server that never stops reaches the bound)."""
    import socket
    import time

    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1.0).close()
        except OSError:
            return True
        time.sleep(0.02)
    return False


def test_closing_the_station_closes_the_udp_stream_and_the_foxglove_server(tmp_path,
                                                                          monkeypatch):
    """A station closed while scope stream udp:// and scope foxglove run: the stream's socket is closed and its thread ended, the Foxglove server no longer accepts a connection and its thread ended, and the scope holds neither."""
    import io
    import socket

    pytest.importorskip("foxglove", reason="the Foxglove SDK (pyrt[foxglove]) is not installed")
    from pyrt.commands import RobotShell
    from pyrt.station.gripper import build_gripper

    monkeypatch.chdir(tmp_path)
    listener = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    listener.bind(("127.0.0.1", 0))
    station = build_gripper(Loop(SimClock()))
    try:
        station.start()
        out = io.StringIO()
        shell = RobotShell(station, out)
        for line in ("scope add encoder", f"scope stream udp://127.0.0.1:"
                     f"{listener.getsockname()[1]} 100", "scope foxglove 0 20"):
            shell.onecmd(line)
        stream, server = station.scope.stream, station.scope.foxglove
        assert stream is not None and server is not None, out.getvalue()
        socket.create_connection(("127.0.0.1", server.port), timeout=5).close()  # serving
        station.runner.sleep(0.2)  # samples flow to both
    finally:
        station.close()
        listener.close()
    assert stream._sock.fileno() == -1
    assert not stream._thread.is_alive()
    assert not server._thread.is_alive()
    assert _wait_refused(server.port)
    assert station.scope.stream is None and station.scope.foxglove is None


def test_scope_close_closes_every_sink_even_when_one_fails_and_may_be_called_twice():
    """Scope.close: a sink whose close raises is logged, the other is still closed; a second close does nothing."""
    import socket

    from pyrt.scope import UdpStream

    class Broken:
        period_ns = 1_000_000

        def offer(self, layout, row):
            pass

        def bind(self, owner):
            pass

        def close(self):
            raise RuntimeError("the SDK would not stop")

    listener = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    listener.bind(("127.0.0.1", 0))
    try:
        scope = Scope()
        stream = UdpStream("127.0.0.1", listener.getsockname()[1], 50)
        scope.start_stream(stream)
        scope.start_foxglove(Broken())
        scope.close()
        assert stream._sock.fileno() == -1 and not stream._thread.is_alive()
        assert scope.stream is None and scope.foxglove is None
        scope.close()
    finally:
        listener.close()
