"""The consoles' `scope` command: grammar, refusals, and a capture read back through the runner."""

from __future__ import annotations

import contextlib
import io

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt.commands.scope import ScopeCommand
from pyrt.errors import CommandError
from pyrt.scheduler import Loop, SimClock
from pyrt.scheduler.runner import Runner
from pyrt.scope import Scope, Source


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
]


@pytest.mark.parametrize("line", BAD)
def test_bad_scope_lines_are_refused(line):
    """Malformed scope commands raise CommandError and leave the scope as it was."""
    cmd, _, scope, _ = make()
    before = (scope.channels, scope.trigger, scope.state, scope.every)
    with pytest.raises(CommandError):
        cmd(line)
    assert (scope.channels, scope.trigger, scope.state, scope.every) == before


@settings(max_examples=150, deadline=None)
@given(st.text(max_size=60))
def test_random_scope_lines_never_crash(line):
    """Any text gives either a result or a CommandError, nothing else."""
    cmd, _, _, _ = make()
    with contextlib.suppress(CommandError):
        cmd(line)
