"""pyrt urdf: movel ... comply, a force held along a tool axis by the wrist sensor while the other
directions follow the line, checked against the simulated arm's truth (the table's contact)."""

from __future__ import annotations

import numpy as np
import pytest
from _urdf_rig import puma_station
from _urdf_rig import settle as _settle
from _urdf_rig import target as _target

from pyrt.errors import CommandError
from pyrt.kinematics.puma import puma560

CHAIN = puma560()
#: The table's height (mm) and where the tool starts above it (tool z down: rpy 180 0 90).
TABLE_MM = 300.0
START = (600.0, 50.0, 320.0, 180.0, 0.0, 90.0)


@pytest.fixture(scope="module")
def puma():
    """One PUMA station on simulated time for this module."""
    yield from puma_station()


def _on_the_table(station, runner) -> None:
    """The tool above the table, then a guarded move down onto it (force=10)."""
    arm = station.arm
    runner.call(station.find("sim").table, "off")
    q = CHAIN.closed_form.inverse(_target(*START), "righty-above-noflip")
    runner.call(arm.move_joints, *np.degrees(q).tolist())
    _settle(station, runner)
    runner.call(station.find("sim").table, f"{TABLE_MM:g}")
    runner.call(arm.move_line, 600, 50, 280, 180, 0, 90, "speed=0.1 force=10")
    _settle(station, runner)
    assert station.last_stop().startswith("force limit"), station.last_stop()


@pytest.mark.parametrize("newtons", [2.0, 5.0])
def test_comply_holds_the_force_along_the_tool_z_while_the_line_runs_in_x_and_y(puma, newtons):
    """On the table after a guarded move, movel 100 mm along y with comply z N (the tool's z points down): the true contact force holds N +- 0.5 N for 2 s of the line (N 2 and 5), the true tool keeps within 0.5 mm of the line in x and y, ends within 0.5 mm of the target in x and y, and the move ends saying the force it holds."""
    station, runner = puma
    arm = station.arm
    _on_the_table(station, runner)
    a = runner.call(lambda: station.plant.truth().tool[:3, 3].copy())
    said = runner.call(arm.move_line, 600, -50, TABLE_MM, 180, 0, 90,
                       f"speed=0.05 comply z {newtons:g}")
    assert said.startswith("moving to")
    trace = []
    t0 = runner.call(lambda: station.plant.truth().time)

    def watch() -> bool:
        tr = station.plant.truth()
        trace.append((tr.time - t0, float(tr.contact[2]), *tr.tool[:3, 3]))
        return not station.busy()

    assert runner.wait_until(watch, 30.0)
    assert station.fault is None
    assert station.last_stop().startswith("at target, complying: the tool presses"), \
        station.last_stop()
    rows = np.array(trace)
    assert rows[-1, 0] > 3.0  # the line took long enough to judge 2 s of it
    window = rows[(rows[:, 0] >= 1.0) & (rows[:, 0] <= 3.0)]
    force = window[:, 1]
    assert float(np.max(np.abs(force - newtons))) <= 0.5, (force.min(), force.max())
    # the other directions on the line: x held, y along it
    off_line = np.abs(rows[:, 2] - a[0])
    assert float(np.max(off_line)) * 1e3 <= 0.5
    y_end = rows[-1, 3]
    assert abs(y_end - (-0.05)) * 1e3 <= 0.5
    # the tool stayed on the table: z at the surface within the contact's give
    assert float(np.max(np.abs(window[:, 4] * 1e3 - TABLE_MM))) <= 1.0
    runner.call(station.find("sim").table, "off")


def test_comply_is_refused_where_it_cannot_hold_and_the_next_move_waits_for_it(puma):
    """comply on movej is refused (only movel complies); comply w 5, comply z x and a missing force are refused with the grammar; while a complying move runs the next move is refused (it starts where the force put the arm) and nothing changes."""
    station, runner = puma
    arm = station.arm
    _settle(station, runner)
    with pytest.raises(CommandError, match="only movel complies"):
        runner.call(arm.move_joints, 0, 45, -180, 0, -45, 0, "comply z 5")
    for opts in ("comply w 5", "comply z x", "comply z", "comply z 5,5"):
        with pytest.raises(CommandError, match="comply") as info:
            runner.call(arm.move_line, *START, opts)
        assert "nothing moved" in str(info.value)
        assert not runner.call(station.busy)
    _on_the_table(station, runner)
    runner.call(arm.move_line, 600, 0, TABLE_MM, 180, 0, 90, "speed=0.05 comply z 3")
    with pytest.raises(CommandError, match="complying record"):
        runner.call(arm.move_line, 600, 50, TABLE_MM, 180, 0, 90)
    _settle(station, runner)
    assert station.fault is None and "complying" in station.last_stop()
    # once it has ended, the next move goes from where the force put the arm
    runner.call(station.find("sim").table, "off")
    runner.call(arm.move_line, *START)
    _settle(station, runner)
    assert station.last_stop() == "at target"
