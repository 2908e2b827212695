"""Register maps for modbus://: the shipped maps, grouping, value coding, refusals naming FILE:LINE."""

from __future__ import annotations

import itertools
import sys
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from pyrt.boards import open_boards
from pyrt.boards.modbus import builtin_map
from pyrt.boards.modbusmap import Place, load_map, parse_map
from pyrt.boards.registers import OUTPUT, BoardKind, Register
from pyrt.cli import main
from pyrt.errors import ConfigError
from pyrt.sim.world import GRIPPER_BOARDS, MANIPULATOR_BOARDS

SERVO = BoardKind("arm-servo", (
    Register("drive", count=2, width=16, signed=True, direction=OUTPUT, off=0),
    Register("enable", direction=OUTPUT, off=0),
    Register("count", count=2, width=32, signed=True),
))
ARM = {"servo": SERVO}

GOOD = """\
unit = 3

[servo.drive]
table = "holding"
address = 10

[servo.enable]
table = "coil"
address = 0

[servo.count]
table = "input"
address = 0
width = 32
word_order = "little"
"""


def test_the_shipped_gripper_map_reads_the_inputs_in_one_request_and_writes_in_one():
    """builtin:gripper: the five inputs are input registers 0..6 (one read), the four outputs
    holding registers 0..3 (one write of all four)."""
    m = load_map(builtin_map("gripper"), GRIPPER_BOARDS)
    [g] = m.read_groups()
    assert (g.unit, g.table, g.address, g.count) == (1, "input", 0, 7)
    [w] = m.write_groups([("gripper", n, 0) for n in ("dac", "cmd", "led_hi", "led_lo")])
    assert (w.table, w.address, w.count) == ("holding", 0, 4)
    assert [p.register.name for p in w.places] == ["cmd", "led_lo", "led_hi", "dac"]


def test_the_shipped_manipulator_map_places_every_register_within_protocol_limits():
    """builtin:manipulator places both boards; no read group exceeds 125 registers."""
    m = load_map(builtin_map("manipulator"), MANIPULATOR_BOARDS)
    groups = m.read_groups()
    assert {g.unit for g in groups} == {1, 2}
    assert all(g.count <= 125 for g in groups if g.table == "input")
    assert sum(len(g.places) for g in groups) == sum(
        r.count for k in MANIPULATOR_BOARDS.values() for r in k.inputs())


def test_writes_group_only_contiguous_places_of_one_table():
    """Writes of drive[0], drive[1] and enable: one holding-register request of two, one coil."""
    m = parse_map(GOOD, ARM)
    groups = m.write_groups([("servo", "drive", 1), ("servo", "enable", 0),
                             ("servo", "drive", 0)])
    assert [(g.unit, g.table, g.address, g.count) for g in groups] == \
        [(3, "coil", 0, 1), (3, "holding", 10, 2)]
    [g] = m.write_groups([("servo", "drive", 1)])
    assert (g.address, g.count) == (11, 1)


@pytest.mark.parametrize("change, line, words", [
    (("[servo.count]\n", "[servo.counts]\n"), 11, "unknown register servo.counts"),
    (('address = 10\n', 'address = 0\n'), 0, None),  # coil and holding differ: no overlap
    (('table = "coil"\naddress = 0', 'table = "holding"\naddress = 11'), 9,
     "overlaps servo.drive[1] at unit 3 holding address 11"),
    (('table = "holding"\naddress = 10', 'table = "register"\naddress = 10'), 4,
     "table must be one of coil, discrete, input, holding"),
    (("width = 32\n", "width = 64\n"), 14, "width out of range"),
    (("width = 32\n", "width = 16\n"), 14, "width out of range: the register is 32 bits"),
    (('table = "holding"\naddress = 10', 'table = "input"\naddress = 10'), 4,
     "is an output: it needs a writable table"),
    (("word_order", "word_orders"), 15, "unknown key 'word_orders'"),
    (("unit = 3\n", "unit = 3\n[servo.drive\n"), 2, "not TOML"),
    (("[servo.enable]\ntable = \"coil\"\naddress = 0\n", ""), 12,
     "does not place servo.enable"),
    (("[servo.drive]\n", "[gripper.drive]\n"), 3, "unknown board 'gripper'"),
])
def test_a_bad_map_is_refused_in_one_line_naming_the_file_and_line(tmp_path, change, line,
                                                                   words):
    """Unknown register or board, overlapping places, a bad table, a width out of range, an
    output in a read-only table, an unknown key, bad TOML, a register not placed: ConfigError
    of one line 'FILE:LINE: ...'."""
    path = tmp_path / "arm.toml"
    text = GOOD.replace(*change)
    path.write_text(text)
    if words is None:
        assert load_map(path, ARM).places
        return
    with pytest.raises(ConfigError) as err:
        load_map(path, ARM)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(f"{path}:{line}: "), msg
    assert words in msg, msg


def test_a_missing_map_file_is_one_line_naming_it(tmp_path):
    """A map path that does not exist: ConfigError naming it."""
    with pytest.raises(ConfigError, match=r"nothere\.toml: cannot read the register map"):
        load_map(tmp_path / "nothere.toml", ARM)


@given(st.integers(-(1 << 31), (1 << 31) - 1), st.sampled_from(["big", "little"]))
def test_a_32_bit_signed_value_round_trips_through_two_words(value, order):
    """encode then decode gives the value back, in either word order."""
    place = Place("servo", SERVO.register("count"), 0, 1, "input", 0, 32, order, True, 1)
    words = place.encode(value)
    assert len(words) == 2 and all(0 <= w <= 0xFFFF for w in words)
    assert place.decode(words) == value


def test_scale_multiplies_what_is_read_and_divides_what_is_written():
    """scale 10: the device's 7 reads as 70; writing 70 sends 7."""
    place = Place("servo", SERVO.register("drive"), 0, 1, "holding", 0, 16, "big", True, 10)
    assert place.decode([7]) == 70 and place.encode(70) == [7]
    assert place.decode([0xFFFF]) == -10


def test_modbus_without_pymodbus_is_a_config_error_saying_how_to_install_it(monkeypatch):
    """With pymodbus missing, a modbus:// URL is a ConfigError naming pyrt[modbus]."""
    monkeypatch.setitem(sys.modules, "pymodbus.client", None)
    url = f"modbus://127.0.0.1:1?map={Path(builtin_map('gripper'))}"
    with pytest.raises(ConfigError, match=r"pip install 'pyrt\[modbus\]'"):
        open_boards(url, "gripper", GRIPPER_BOARDS)


def test_a_modbus_url_without_a_map_is_refused():
    """modbus://HOST:PORT alone: ConfigError asking for ?map=FILE."""
    with pytest.raises(ConfigError, match=r"needs a register map"):
        open_boards("modbus://127.0.0.1:1", "gripper", GRIPPER_BOARDS)


def test_board_sim_refuses_a_bad_map_in_one_line_and_map_without_modbus(tmp_path, capsys):
    """pyrt board-sim gripper --modbus with a map that places an unknown register: exit 1 and
    one line FILE:LINE; --map without --modbus: exit 1 saying they go together."""
    bad = tmp_path / "cage.toml"
    text = builtin_map("gripper").read_text().replace("[gripper.pc]", "[gripper.pd]")
    bad.write_text(text)
    line = text.splitlines().index("[gripper.pd]          # 8155 PC: bit 0 jog OPEN, "
                                   "bit 1 jog CLOSE, active low") + 1
    assert main(["board-sim", "gripper", "--modbus", "127.0.0.1:0", "--map", str(bad)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{bad}:{line}: unknown register gripper.pd" in err[0], err
    assert main(["board-sim", "gripper", "--map", str(bad)]) == 2  # a usage error
    assert "--map goes with --modbus" in capsys.readouterr().err


@given(st.sets(st.integers(0, 400), min_size=1, max_size=60),
       st.sampled_from(["holding", "coil"]))
def test_groups_are_the_fewest_contiguous_runs_within_the_protocol_limits(addresses, table):
    """Any placement: every place is in exactly one group, each group is one contiguous run
    of one table within the request limit, and there are as many groups as the runs need."""
    regs = [Register(f"r{a}", width=1, direction=OUTPUT) for a in sorted(addresses)]
    kind = BoardKind("io", tuple(regs))
    text = "".join(f'[b.r{a}]\ntable = "{table}"\naddress = {a}\n' for a in sorted(addresses))
    m = parse_map(text, {"b": kind})
    groups = m.write_groups([("b", r.name, 0) for r in regs])
    placed = [p.address for g in groups for p in g.places]
    assert sorted(placed) == sorted(addresses)
    limit = 1968 if table == "coil" else 123
    for g in groups:
        assert [p.address for p in g.places] == list(range(g.address, g.address + g.count))
        assert g.count <= limit and g.table == table
    ordered = sorted(addresses)
    runs = 1 + sum(1 for a, b in itertools.pairwise(ordered) if b != a + 1)
    assert len(groups) == runs  # at most 60 places: no run reaches the limit
