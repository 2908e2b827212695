"""The scope's doors: one show's work is bounded, and files land only in the scope's directory."""

from __future__ import annotations

import io
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from _server_rig import served

from pyrt.commands.scope import MAX_SHOW
from pyrt.errors import CommandError
from pyrt.scheduler import Loop, SimClock
from pyrt.scope import Scope, Source, confine


class Ramp:
    def __init__(self):
        self.n = 0.0

    def step(self, now_ns: int) -> None:
        self.n += 1.0


def _rig(capacity: int) -> tuple[Loop, Scope]:
    loop = Loop(SimClock())
    ramp = Ramp()
    scope = Scope(capacity=capacity)
    loop.attach(ramp.step)
    loop.attach(scope.sample)
    scope.add("n", Source.attr(ramp, "n"))
    return loop, scope


# -- bounded reads ---------------------------------------------------------------------------


@pytest.mark.parametrize("mode", ["roll", "auto", "normal"])
def test_read_last_copies_only_the_samples_asked_for(mode):
    """read(last=N) gives the frame's last N samples (a complete frame, a roll, a
    triggered frame still filling), its trigger point kept where it is in them."""
    loop, scope = _rig(1000)
    if mode == "normal":
        scope.set_trigger("n", 600.5, pre=0.5)  # the frame: 500 before 601, 500 after
    scope.run(mode)
    loop.run(900 if mode == "normal" else 2500)
    whole = scope.read()
    part = scope.read(last=150)
    assert part.t_ns.size == 150
    assert np.array_equal(part.data, whole.data[-150:])
    assert np.array_equal(part.t_ns, whole.t_ns[-150:])
    if mode == "normal":
        assert scope.state == "triggered"
        assert whole.column("n")[whole.trigger_index] == 601.0
        assert part.trigger_index is None  # the trigger point is before the last 150
        near = scope.read(last=450)
        assert near.column("n")[near.trigger_index] == 601.0


def test_read_last_of_a_held_frame_keeps_its_trigger_point():
    """A complete triggered frame read by its last N keeps the trigger's index into them."""
    loop, scope = _rig(100)
    scope.set_trigger("n", 50.5, pre=0.2)
    scope.run("single")
    loop.run(400)
    part = scope.read(last=90)
    assert part.t_ns.size == 90 and part.column("n")[part.trigger_index] == 51.0
    assert scope.read(last=10**6).t_ns.size == 100


@pytest.mark.parametrize("n", ["490000", "5001", "0", "٣", "-1", "1e3"])
def test_scope_show_beyond_the_limit_is_refused_naming_it(n):
    """scope show N takes 1..MAX_SHOW; a larger N is refused, naming the limit and
    'scope save', before the scope is read."""
    from pyrt.commands.scope import ScopeCommand

    _loop, scope = _rig(100)
    calls = []

    class Runner:
        def call(self, fn, *args, **kw):
            calls.append(getattr(fn, "__name__", ""))
            return fn(*args)

    cmd = ScopeCommand(Runner(), scope, lambda name: None, list, io.StringIO())
    with pytest.raises(CommandError, match=rf"1\.\.{MAX_SHOW} .*'scope save FILE'"):
        cmd(f"show {n}")
    assert "read" not in calls


def test_an_unprivileged_client_gets_a_bounded_show():
    """Over the DAQ link, without the token: 'scope show 490000' is refused with the limit;
    'scope show 5000' prints at most 5000 rows."""
    with served() as sv:
        op = sv.operator()
        op.command("scope add encoder")
        op.command("scope length 100000")
        op.command("scope run roll")
        sv.runner.call(lambda: None)
        sv.runner.sleep(6.0)
        c = sv.client()
        reply = c.request("scope show 490000")
        assert reply.code == "command" and f"1..{MAX_SHOW}" in reply.text, reply
        rows = c.command(f"scope show {MAX_SHOW}")
        assert rows[0] == "t_s encoder" and len(rows) == MAX_SHOW + 1


# -- files only inside the scope's directory ------------------------------------------------


def test_confine_keeps_names_inside_the_directory(tmp_path):
    """A relative or absolute name inside the directory is taken; '..', an absolute path
    elsewhere and a link pointing out are refused, naming the directory."""
    (tmp_path / "sub").mkdir()
    os.symlink("/tmp", tmp_path / "out")
    assert confine("a.csv", tmp_path, "scope save") == tmp_path.resolve() / "a.csv"
    assert confine("sub/a.csv", tmp_path, "scope save") == tmp_path.resolve() / "sub" / "a.csv"
    assert confine(tmp_path / "b.csv", tmp_path, "x") == tmp_path.resolve() / "b.csv"
    for bad in ("../a.csv", "sub/../../a.csv", "/etc/a.csv", "out/a.csv", ".", ""):
        with pytest.raises(CommandError, match=r"outside .*: the scope writes files only"):
            confine(bad, tmp_path / "sub" if bad == "" else tmp_path, "scope save")


def _gripper(cwd: Path, script: str, *extra: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "pyrt", "gripper", "--speed", "max", *extra],
                          input=script, capture_output=True, text=True, timeout=120, cwd=cwd)


def test_scope_save_writes_only_inside_the_working_directory(tmp_path):
    """A piped console: 'scope save ../x.csv' and an absolute path elsewhere are refused
    (nothing written); 'scope save x.csv' writes into the working directory."""
    work = tmp_path / "work"
    work.mkdir()
    script = ("scope add encoder\nscope run roll\nsleep 0.1\nscope save ../x.csv\n"
              f"scope save {tmp_path / 'y.csv'}\nscope plot ../z.png\nscope save x.csv\n")
    done = _gripper(work, script, "-k")  # -k: the refused lines fail the script, it runs on
    assert done.returncode == 1
    assert done.stdout.count("the scope writes files only inside the working directory") == 3
    assert sorted(p.name for p in tmp_path.rglob("*.*")) == ["x.csv"]
    assert (work / "x.csv").is_file()


def test_scope_dir_names_the_directory_files_go_into(tmp_path):
    """--scope-dir D: 'scope save x.csv' writes D/x.csv; '../x.csv' is refused naming
    --scope-dir; a directory that is not there is a start-up error."""
    d = tmp_path / "captures"
    d.mkdir()
    done = _gripper(tmp_path, "scope add encoder\nscope run roll\nsleep 0.1\n"
                    "scope save x.csv\nscope save ../y.csv\n", "--scope-dir", str(d))
    assert (d / "x.csv").is_file() and not (tmp_path / "y.csv").exists()
    assert "the directory --scope-dir names" in done.stdout
    done = _gripper(tmp_path, "", "--scope-dir", str(tmp_path / "nope"))
    assert done.returncode != 0 and "--scope-dir" in done.stderr and "no such directory" in done.stderr
