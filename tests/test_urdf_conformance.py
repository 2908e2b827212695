"""The component contract of tests/test_conformance.py, run on the pyrt urdf station (the
PUMA 560), built through its factory as 'pyrt urdf' builds it.

The arm carries its own weight: the servo holds it from the first tick, so "driven" here
means an actuator that moves the arm (a move that runs, or a joint of the simulated arm
moving), not an amplifier that holds it still; the registers of a trip are checked in
tests/test_urdf_station.py (every DAC and enable 0 in the tick of the fault).
"""

from __future__ import annotations

import argparse
import math

import numpy as np
import pytest
import test_conformance as conf
from test_conformance import (
    test_a_reading_record_changes_nothing,
    test_a_record_not_marked_moves_never_starts_an_actuator,
    test_every_component_has_a_name,
    test_every_nasty_word_in_every_argument_gives_a_command_error,
    test_every_record_has_help_a_grammar_and_a_class,
    test_every_signal_has_units_and_reads_a_number,
    test_the_tables_derived_from_the_records_agree,
)

from pyrt.scheduler import Loop, SimClock
from pyrt.station.urdf import URDF, UrdfStation

__all__ = [
    "test_a_reading_record_changes_nothing",
    "test_a_record_not_marked_moves_never_starts_an_actuator",
    "test_every_component_has_a_name",
    "test_every_nasty_word_in_every_argument_gives_a_command_error",
    "test_every_record_has_help_a_grammar_and_a_class",
    "test_every_signal_has_units_and_reads_a_number",
    "test_the_tables_derived_from_the_records_agree",
]

#: A joint of the simulated arm moving faster than this (deg/s) is driven.
MOVING_DEG_S = 0.5

_driven, _settings = conf._driven, conf._settings


def _urdf_driven(station) -> list[str]:
    if not isinstance(station, UrdfStation):
        return _driven(station)
    out = [f"the arm {station.arm.state}"] if station.arm.state != "idle" else []
    qd = np.degrees(station.plant.truth().qd)
    out += [f"q{j + 1} at {v:.3f} deg/s" for j, v in enumerate(qd) if abs(v) > MOVING_DEG_S]
    return out


def _urdf_settings(station) -> tuple:
    if not isinstance(station, UrdfStation):
        return _settings(station)
    board, arm = station.board, station.arm
    regs = tuple(board.read(r.name, j) for r in board.kind.outputs() for j in range(r.count))
    return (regs, arm.state, arm.powered, arm.servo.knots.tobytes(), arm.servo.gains.tobytes(),
            station.plant.table_z, len(station.motion), arm.last_stop)


@pytest.fixture(autouse=True)
def _urdf_rules(monkeypatch):
    monkeypatch.setattr(conf, "_driven", _urdf_driven)
    monkeypatch.setattr(conf, "_settings", _urdf_settings)
    monkeypatch.setitem(conf._SAMPLES, "UrdfSim.table", [["-2000"], ["off"]])
    for frame in ("tool", "coord"):
        monkeypatch.setitem(conf._SAMPLES, f"UrdfArm.{frame}", [["0", "0", "50", "0", "0", "0"],
                                                                 ["0"] * 6])


@pytest.fixture
def robot():
    station = URDF.build(Loop(SimClock()), argparse.Namespace(boards=None, urdf=None, start=None))
    runner = station.start()
    assert runner.wait_until(lambda: station.arm.powered and not station.busy(), 5.0)
    runner.sleep(0.2)
    yield station, runner
    station.close()


def test_the_holding_arm_is_not_driven(robot):
    """At start the servo holds the PUMA against gravity: amplifiers on, no move, the truth still."""
    station, runner = robot
    assert station.arm.powered
    assert runner.call(lambda: _urdf_driven(station)) == []
    assert math.isfinite(runner.call(lambda: station.signals()[0][1].read()))
