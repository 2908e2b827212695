"""The consoles' `scope` command: grammar, refusals, and a capture read back through the runner."""

from __future__ import annotations

import contextlib
import io
import re

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt.commands.scope import ScopeCommand
from pyrt.errors import CommandError
from pyrt.scheduler import Loop, SimClock
from pyrt.scheduler.runner import Runner
from pyrt.scope import Scope, Source


@pytest.fixture(autouse=True)
def _in_tmp(tmp_path, monkeypatch):
    """Each test runs in its own directory: the scope writes files only inside the
    working directory."""
    monkeypatch.chdir(tmp_path)


class Plant:
    def __init__(self):
        self.n = 0
        self.x = 0.0

    def step(self, now_ns):
        self.n += 1
        self.x = float(self.n % 100)


def make():
    loop = Loop(SimClock())
    plant = Plant()
    scope = Scope(capacity=200)
    loop.attach(plant.step)
    loop.attach(scope.sample)
    runner = Runner(loop)
    runner.start()
    names = {"plant.x": Source.attr(plant, "x"), "plant.n": Source.attr(plant, "n")}

    def resolve(name):
        try:
            return names[name.lower()]
        except KeyError:
            raise CommandError(f"no channel {name!r}") from None

    out = io.StringIO()
    return ScopeCommand(runner, scope, resolve, lambda: sorted(names), out), runner, scope, out


def test_capture_and_show_through_the_runner(tmp_path):
    """add, trigger, single, then show/save read the captured frame back."""
    cmd, runner, scope, out = make()
    cmd("add plant.x plant.n")
    cmd("trigger plant.x 50 rising pre 0.25")
    cmd("single")
    runner.sleep(1.0)
    cmd("show 3")
    lines = out.getvalue().splitlines()
    assert lines[-4] == "t_s plant.x plant.n"
    assert scope.frames == 1 and scope.state == "done"
    cmd(f"save {tmp_path / 'f.csv'}")
    assert (tmp_path / "f.csv").read_text().splitlines()[0] == "t_s,plant.x,plant.n"


def test_stop_then_save_writes_the_partial_frame_and_says_so(tmp_path):
    """'scope run', stop before the frame fills, save: the samples taken, counted, in the file."""
    cmd, runner, scope, out = make()
    assert scope.mode == "auto"
    cmd("add plant.x")
    cmd("run")
    runner.sleep(0.05)  # 50 of the 200 samples
    cmd("stop")
    cmd(f"save {tmp_path / 'p.csv'}")
    said = out.getvalue().splitlines()[-1]
    rows = (tmp_path / "p.csv").read_text().splitlines()[1:]
    assert said.startswith(f"saved {len(rows)} samples of 1 channel(s) (a partial frame: of 200)")
    assert 0 < len(rows) < 200


def test_status_lists_available_channels():
    """`scope` alone prints the status and the channels the robot offers."""
    cmd, _, _, out = make()
    cmd("")
    text = out.getvalue()
    assert "scope stopped" in text and "available: plant.n, plant.x" in text


BAD = [
    "add", "add nope", "remove plant.x", "trigger plant.x", "trigger plant.x abc",
    "trigger plant.x 1 sideways", "every 0", "every x", "run warp", "single now",
    "show x", "save", "save a.txt", "frobnicate", "trigger 'unclosed",
    "length", "length 1", "length x", "length 1000001", "help nope", "stop now",
    "every \u0663", "length \u0663\u0660\u0660",  # digits of another script are no number
]


@pytest.mark.parametrize("line", BAD)
def test_bad_scope_lines_are_refused(line):
    """Malformed scope commands raise CommandError and leave the scope as it was."""
    cmd, _, scope, _ = make()
    before = (scope.channels, scope.trigger, scope.state, scope.every, scope.capacity)
    with pytest.raises(CommandError):
        cmd(line)
    assert (scope.channels, scope.trigger, scope.state, scope.every, scope.capacity) == before


@settings(max_examples=150, deadline=None)
@given(st.text(max_size=60))
def test_random_scope_lines_never_crash(line):
    """Any text gives either a result or a CommandError, nothing else."""
    cmd, _, _, _ = make()
    with contextlib.suppress(CommandError):
        cmd(line)


# -- plots: the gripper's own signals, units and hex, time as in the CSV ---------------


def _gripper_capture(tmp_path):
    """A gripper station on virtual time: ram:4A (a RAM byte, hex) and encoder
    (counts) captured while the jaws close, saved to CSV; the frame too."""
    from pyrt.commands import RobotShell
    from pyrt.station.gripper import build_gripper

    station = build_gripper(Loop(SimClock()))
    station.start()
    out = io.StringIO()
    shell = RobotShell(station, out)
    for line in ("I", "wait", "sleep 1.4", "scope add ram:4A encoder", "scope run roll",
                 "P-1B86", "sleep 0.5", "scope stop", f"scope save {tmp_path / 'f.csv'}"):
        shell.onecmd(line)
    frame = station.runner.call(station.scope.read)
    return station, shell, out, frame


def test_scope_plot_names_units_shows_hex_and_keeps_the_csvs_time(tmp_path):
    """scope plot: each y axis names its units, the RAM byte's ticks are hex, the time axis starts where the CSV does."""
    pytest.importorskip("matplotlib")
    import numpy as np

    from pyrt.scope.export import frame_figure

    station, shell, out, frame = _gripper_capture(tmp_path)
    try:
        shell.onecmd(f"scope plot {tmp_path / 'f.png'}")
        assert (tmp_path / "f.png").read_bytes()[:4] == b"\x89PNG"
        assert "error" not in out.getvalue().lower()
        fig = frame_figure(frame)
        fig.canvas.draw()
        ram, enc = fig.axes
        assert ram.get_ylabel() == "ram:4A (byte, hex)"
        assert enc.get_ylabel() == "encoder (counts)"
        assert enc.get_xlabel() == "loop time (s)"
        labels = [(t.get_position()[1], t.get_text()) for t in ram.get_yticklabels()]
        assert len(labels) >= 2
        assert all(text == format(round(v), "02X") for v, text in labels)
        assert ram.yaxis.get_major_formatter()(0x4A, 0) == "4A"
        assert enc.yaxis.get_major_formatter()(200, 0) != "C8"  # counts stay decimal
        csv = np.loadtxt(tmp_path / "f.csv", delimiter=",", skiprows=1)
        x = ram.lines[0].get_xdata()
        assert csv[0, 0] > 1.0 and x[0] == pytest.approx(csv[0, 0], abs=1e-9)
        assert x[-1] == pytest.approx(csv[-1, 0], abs=1e-9)
    finally:
        station.close()


def test_a_channel_without_units_says_so_on_its_axis():
    """A source with no units given is labelled so, never left bare."""
    import numpy as np

    from pyrt.scope import Frame
    from pyrt.scope.export import axis_label

    frame = Frame(np.arange(3), np.zeros((3, 2)), ("a", "b"), None, "roll",
                  units=("N", ""), formats=(".4g", "04X"))
    assert axis_label(frame, 0) == "a (N)"
    assert axis_label(frame, 1) == "b (units not given, hex)"


def test_scope_plot_without_matplotlib_is_one_line_and_writes_nothing(tmp_path):
    """Without matplotlib, scope plot in a piped console prints the install hint, writes no file, and the console goes on."""
    import subprocess
    import sys

    script = ("scope add ram:4A\nscope run roll\nsleep 0.2\n"
              f"scope plot {tmp_path / 'f.png'}\nW\n")
    code = ("import sys; sys.modules['matplotlib'] = None\n"
            "from pyrt.cli import main; sys.exit(main(['gripper', '--speed', 'max', '-k']))")
    done = subprocess.run([sys.executable, "-c", code], input=script, capture_output=True,
                          text=True, timeout=60, cwd=tmp_path)
    # the refused plot fails the piped script (-k: it runs on), named once on stderr
    assert done.returncode == 1, done.stderr
    assert [ln.split(": ")[1] for ln in done.stderr.splitlines()] == ["stdin:4"]
    hint = [ln for ln in done.stdout.splitlines() if "matplotlib" in ln]
    assert len(hint) == 1 and "pip install 'pyrt[plot]'" in hint[0]
    assert "Traceback" not in done.stderr
    assert not (tmp_path / "f.png").exists()
    assert "CMD: W\n" in done.stdout  # the next command still ran


# -- the operator's first hour: a single trigger, the pre-trigger fill, what is said --------


def _gripper_shell():
    from pyrt.commands import RobotShell
    from pyrt.station.gripper import build_gripper

    station = build_gripper(Loop(SimClock()))
    station.start()
    out = io.StringIO()
    shell = RobotShell(station, out)

    def run(*lines: str) -> str:
        out.seek(0)
        out.truncate()
        for line in lines:
            shell.onecmd(line)
        return out.getvalue()

    run("I")
    return station, run


def test_a_single_trigger_never_misses_silently_and_captures_the_next_event(tmp_path):
    """The issue's session: the crossing during the 3.2 s pre-trigger fill is said to be not taken, the advice fits single mode, and the next crossing after the fill makes the frame (CSV header with units)."""
    station, run = _gripper_shell()
    said = run("scope add encoder", "scope trigger encoder -3000 falling pre 0.2", "scope single")
    assert "3200 samples (3.2 s) before it" in said
    assert "armed (single), pre-trigger 0 % filled: the trigger arms when it is full" in said
    said = run("P E47A", "wait", "sleep 13", "scope", "scope show")
    assert "scope armed (single), pre-trigger full" in said and "frames: 0" in said
    assert "1 trigger event came while the pre-trigger part filled and was not taken" in said
    show = said.splitlines()[-1]
    assert show.startswith("error: scope: nothing captured yet: armed (single), pre-trigger "
                           "full: waiting for encoder falling through -3000")
    assert "scope run, then let time pass" not in said
    run("P 0000", "wait", "P E47A", "wait", "sleep 13")  # the next crossing, after the fill
    assert station.runner.call(lambda: (station.scope.state, station.scope.frames)) == ("done", 1)
    said = run(f"scope save {tmp_path / 'f.csv'}")
    assert said.startswith("saved 16000 samples of 1 channel(s) to ")
    rows = (tmp_path / "f.csv").read_text().splitlines()
    assert rows[0] == "t_s,encoder [counts]"
    levels = [float(r.split(",")[1]) for r in rows[3200:3202]]  # rows[0] is the header
    assert levels[0] > -3000 >= levels[1]  # the trigger point is sample 3200


def test_scope_run_stop_every_length_remove_and_trigger_off_say_what_they_did():
    """Each scope change answers with what it did, in loop time where it can."""
    _, run = _gripper_shell()
    run("scope add encoder dac")
    assert run("scope every 2") == ("sampling every 2 tick(s) (0.002 s); a frame of 16000 "
                                    "samples (32 s)\n")
    assert run("scope length 4000") == "record length 4000 samples (8 s)\n"
    said = run("scope run roll")
    assert said.startswith("scope roll: the latest samples, always; frames of 4000 samples (8 s)")
    said = run("sleep 1", "scope stop")  # 1 s at every 2 ticks: 500 samples and the calls'
    assert re.fullmatch(r"scope stopped \(it was rolling\); a partial frame of 50\d samples "
                        r"is kept\n", said), said
    assert run("scope trigger off") == "trigger off\n"
    assert run("scope remove dac") == "removed dac; scope channels: encoder\n"
    assert "scope stopped (roll)" in run("scope")


def test_help_scope_documents_every_sub_command():
    """'help scope' prints every sub-command (every, remove, trigger off, length ...), and 'scope help trigger' the trigger's help."""
    from pyrt.commands.scope import SUBCOMMAND_HELP

    _, run = _gripper_shell()
    text = run("help scope")
    for usage in ("scope every N", "scope remove CH", "scope trigger off", "scope length N",
                  "scope trigger CH LEVEL [rising|falling] [pre FRACTION]", "scope single",
                  "scope run [normal|auto|roll|single]", "scope stop", "scope help [SUB]",
                  "arms the trigger only when it is full", "64 MiB"):
        assert usage in " ".join(text.split()), usage
    assert all(len(line) <= 100 for line in text.splitlines())
    assert set(SUBCOMMAND_HELP) >= {"add", "remove", "trigger", "every", "length", "run",
                                    "single", "stop", "show", "save", "plot"}
    said = run("scope help trigger")
    assert said.startswith("scope trigger CH LEVEL") and "scope trigger off" in said


# -- scope plot writes the format its extension names ---------------------------------------

PLOT_MAGIC = [("f.png", b"\x89PNG"), ("f.svg", b"<?xml"), ("f.PDF", b"%PDF")]


@pytest.mark.parametrize(("name", "magic"), PLOT_MAGIC)
def test_scope_plot_writes_the_format_its_extension_names(tmp_path, name, magic):
    """scope plot FILE.svg writes SVG, .pdf PDF, .png PNG: the bytes are the named format's."""
    pytest.importorskip("matplotlib")
    cmd, runner, _scope, out = make()
    cmd("add plant.x")
    cmd("run roll")
    runner.sleep(0.05)
    cmd(f"plot {tmp_path / name}")
    assert (tmp_path / name).read_bytes()[:len(magic)] == magic
    assert out.getvalue().splitlines()[-1] == f"plotted {tmp_path / name}"


@pytest.mark.parametrize("name", ["s2", "f.jpg", "f.csv", "f.png.txt"])
def test_scope_plot_refuses_a_format_it_cannot_write_before_reading_the_frame(tmp_path, name):
    """A name without a plot extension is refused naming the formats (even before any
    capture), and no file is written."""
    cmd, _runner, _scope, _out = make()
    with pytest.raises(CommandError, match=r"one of \.png, \.svg or \.pdf"):
        cmd(f"plot {tmp_path / name}")
    assert list(tmp_path.iterdir()) == []


def test_scope_show_and_plot_during_a_move_show_the_move_so_far(tmp_path):
    """'scope run' (auto, no trigger), a move, one second in: show and save give the move so
    far (a frame is 16 s), the encoder falling; no 'nothing captured yet'."""
    station, run = _gripper_shell()
    run("scope add encoder", "scope run")
    said = run("P E47A", "sleep 1", "scope show 3", f"scope save {tmp_path / 'so-far.csv'}")
    assert "nothing captured" not in said
    lines = said.splitlines()
    assert lines[0] == "t_s encoder"
    assert lines[-1].startswith("saved ") and "(a partial frame: of 16000)" in lines[-1]
    rows = (tmp_path / "so-far.csv").read_text().splitlines()[1:]
    assert 900 <= len(rows) <= 1100  # one second of 1 ms samples, as they came
    enc = [float(r.split(",")[1]) for r in rows]
    assert enc[-1] < enc[0]  # the jaws are closing
    assert station.runner.call(lambda: station.scope.state) == "armed"  # still acquiring


def test_the_scope_refuses_a_text_channel_and_does_not_offer_one():
    """scope add gripper.where (a text signal): one error line saying the scope samples numbers and what reads text; no channel added; 'scope' alone does not offer the text signals."""
    station, run = _gripper_shell()
    try:
        before = station.scope.channels
        for name in ("gripper.where", "gripper.statusline", "last_stop"):
            said = run(f"scope add {name}")
            assert "error" in said and "is text" in said and "scope samples numbers" in said
            assert "'status' or 'show' reads it" in said, said
            assert station.scope.channels == before
        offered = run("scope")
        assert "gripper.encoder" in offered or "encoder" in offered
        assert "where" not in offered and "statusline" not in offered
        assert "last_stop" not in offered
    finally:
        station.close()
