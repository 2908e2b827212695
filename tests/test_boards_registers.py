"""Board kinds declare their registers: Register and BoardKind validation, the generic
RegisterBoard, and the built-in kinds' register files with their typed views over them."""

from __future__ import annotations

import pytest

from pyrt.boards import open_boards
from pyrt.boards.dataconcentrator import DataConcentrator
from pyrt.boards.gripper import DAC, DAC_NULL, LED_LO, GripperBoard
from pyrt.boards.kinds import DATACONCENTRATOR, GRIPPER_CAGE, TIO10_KIND
from pyrt.boards.registers import (
    INPUT,
    OUTPUT,
    BoardKind,
    Register,
    RegisterBoard,
    outputs_are_off,
    outputs_off,
)
from pyrt.boards.tio10 import AWO_BITS, TIO10
from pyrt.errors import ConfigError
from pyrt.sim.cards import add_counts, add_pulses, set_adc, set_rtc
from pyrt.sim.world import World

#: A two-joint arm's servo board: per joint a drive register and an encoder counter, an enable.
SERVO = BoardKind("arm-servo", (
    Register("drive", count=2, width=16, signed=True, direction=OUTPUT, off=0,
             units="DAC counts", doc="motor drive per joint"),
    Register("enable", direction=OUTPUT, off=0, doc="1: drives on"),
    Register("count", count=2, width=32, signed=True, units="counts", doc="encoder counts"),
    Register("home", width=1, doc="home switch"),
))


# -- declarations ----------------------------------------------------------------------------


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"name": "Drive"}, "lower-case"),
    ({"name": "x" * 33}, "at most 32"),
    ({"name": "a", "width": 0}, "width must be 1..32"),
    ({"name": "a", "width": 33}, "width must be 1..32"),
    ({"name": "a", "width": True}, "width must be 1..32"),
    ({"name": "a", "count": 0}, "count must be"),
    ({"name": "a", "signed": True, "width": 1}, "at least 2 bits"),
    ({"name": "a", "direction": "both"}, "direction must be"),
    ({"name": "a", "off": 0}, "an input has no off value"),
    ({"name": "a", "direction": OUTPUT, "width": 8, "off": 256}, "does not fit"),
    ({"name": "a", "direction": OUTPUT, "count": 2, "off": (0,)}, "1 off values for 2"),
])
def test_a_bad_register_declaration_is_refused(kwargs, message):
    """A bad name, width, count, direction or off value is a ConfigError saying which."""
    with pytest.raises(ConfigError, match=message):
        Register(**kwargs)


def test_a_kind_refuses_duplicate_names_and_an_empty_declaration():
    """Two registers of one name, no register at all, or a bad kind name are ConfigErrors."""
    with pytest.raises(ConfigError, match="declares register 'a' twice"):
        BoardKind("k", (Register("a"), Register("a", width=8)))
    with pytest.raises(ConfigError, match="declares no register"):
        BoardKind("k", ())
    with pytest.raises(ConfigError, match="kind's name"):
        BoardKind("K k", (Register("a"),))


def test_a_kind_lists_inputs_and_outputs_in_declared_order_and_fingerprints_them():
    """inputs()/outputs() keep the declared order; the fingerprint changes with any register."""
    assert [r.name for r in SERVO.inputs()] == ["count", "home"]
    assert [r.name for r in SERVO.outputs()] == ["drive", "enable"]
    assert SERVO.input_count == 3 and SERVO.tag == f"arm-servo@{SERVO.fingerprint}"
    wider = BoardKind("arm-servo", (*SERVO.registers[:2],
                                    Register("count", count=2, width=24, signed=True),
                                    SERVO.registers[3]))
    assert wider.fingerprint != SERVO.fingerprint
    assert len({GRIPPER_CAGE.tag, TIO10_KIND.tag, DATACONCENTRATOR.tag}) == 3


def test_register_ranges_follow_width_and_signedness():
    """A signed 16-bit register holds -32768..32767, an unsigned 8-bit 0..255; bools are not ints."""
    drive = SERVO.register("drive")
    assert (drive.low, drive.high) == (-32768, 32767)
    assert drive.fits(-32768) and not drive.fits(32768) and not drive.fits(True)
    assert GRIPPER_CAGE.register("dac").high == 255
    with pytest.raises(ValueError, match="no register 'torque'"):
        SERVO.register("torque")


# -- the generic board ---------------------------------------------------------------------------


def test_register_board_holds_writes_and_inputs_both_sides():
    """The controller writes outputs and reads everything; the world sets inputs and reads
    outputs; the snapshot holds every input in declared order."""
    board = RegisterBoard(SERVO)
    assert board.read("drive", 1) == 0 and board.snapshot() == [0, 0, 0]
    board.write("drive", -300, 1)
    board.write("enable", 1)
    assert board.output("drive", 1) == -300 and board.read("drive", 1) == -300
    board.set_input("count", -5, 1)
    board.set_input("home", 1)
    assert board.read("count", 1) == -5 and board.snapshot() == [0, -5, 1]
    assert board.writes == 2 and board.values("drive") == [0, -300]


@pytest.mark.parametrize(("action", "message"), [
    (lambda b: b.write("drive", 40000), r"value must be an integer -32768\.\.32767"),
    (lambda b: b.write("drive", 1, 2), r"index must be 0\.\.1"),
    (lambda b: b.write("drive", 1.5), "value must be an integer"),
    (lambda b: b.write("count", 1), "count is an input"),
    (lambda b: b.write("speed", 1), "no register 'speed'"),
    (lambda b: b.read("count", -1), "index must be"),
    (lambda b: b.set_input("drive", 1), "drive is an output"),
    (lambda b: b.set_input("home", 2), r"value must be an integer 0\.\.1"),
    (lambda b: b.output("count"), "count is an input"),
])
def test_register_board_refuses_bad_accesses_and_changes_nothing(action, message):
    """Width, sign, index, direction and name are checked: ValueError, nothing changes."""
    board = RegisterBoard(SERVO)
    with pytest.raises(ValueError, match=message):
        action(board)
    assert board.writes == 0 and board.snapshot() == [0, 0, 0]
    assert board.values("drive") == [0, 0]


def test_outputs_off_writes_the_declared_off_values_and_world_uses_it():
    """outputs_off writes every declared off value; a World's watchdog action does that for
    every board it serves."""
    with open_boards("sim:", "arm", {"servo": SERVO}) as opened:
        boards = opened.simulated  # the world's side
        board = boards["servo"]
        board.write("drive", 123, 0)
        board.write("enable", 1)
        world = World("arm", boards)
        assert not world.outputs_are_off()
        world.outputs_off()
        assert world.outputs_are_off() and board.values("drive") == [0, 0]
        assert board.read("enable") == 0
        assert world.info() == {}


def test_a_world_wants_in_process_boards_and_a_one_word_name():
    """World refuses a name with spaces and boards that are not in process."""
    boards = open_boards("sim:", "arm", {"servo": SERVO})
    with pytest.raises(ConfigError, match="one ASCII word"):
        World("my arm", boards)
    with pytest.raises(ConfigError, match="in-process"):
        World("arm", object())  # type: ignore[arg-type]


# -- the built-in kinds --------------------------------------------------------------------------


def test_tio10_view_writes_registers_and_off_is_the_reflex():
    """arm writes armed[ch] = 1 (a period must be loaded, the view refuses otherwise), disarm 0;
    off disarms every motor channel and sets every all-windings-off bit, leaving the direction
    port alone."""
    view = RegisterBoard(TIO10_KIND)
    tio = TIO10(view)
    with pytest.raises(ValueError, match="no period loaded"):
        tio.arm(7)
    tio.load_period(7, 100)
    tio.select_source(7, 3)
    tio.arm(7)
    tio.write_port(0, 0x80)
    assert tio.armed(7) and tio.source(7) == 3 and view.read("armed", 7) == 1
    assert not outputs_are_off(TIO10_KIND, view)
    outputs_off(TIO10_KIND, view)
    assert not tio.armed(7) and all(tio.bit(*AWO_BITS[c]) for c in AWO_BITS)
    assert tio.read_port(0) == 0x80 and outputs_are_off(TIO10_KIND, view)
    add_pulses(view, 7, 5)
    set_rtc(view, 1_000_000)
    assert view.snapshot() == [0] * 7 + [5, 0, 0, 5000]


def test_dataconcentrator_clear_is_a_write_only_strobe():
    """clr[a] = 1 clears counter a; clr cannot be read; the snapshot is counters then ADCs."""
    view = RegisterBoard(DATACONCENTRATOR)
    dc = DataConcentrator(view)
    add_counts(view, 168, 42)
    set_adc(view, 3, 1000)
    snap = view.snapshot()
    assert len(snap) == DATACONCENTRATOR.input_count == 256 + 16
    assert snap[168] == 42 and snap[256 + 3] == 1000
    with pytest.raises(ValueError, match="write-only"):
        view.read("clr", 168)
    view.write("clr", 1, 168)
    assert dc.read_counter(168) == 0 and view.read("cnt", 168) == 0


def test_a_clear_strobe_names_an_input_of_as_many_registers():
    """A kind whose strobe clears no input, or one of another count, is refused."""
    cnt = Register("cnt", count=2, width=8)
    with pytest.raises(ConfigError, match="clears"):
        BoardKind("k", (cnt, Register("clr", count=2, direction=OUTPUT, clears="nope")))
    with pytest.raises(ConfigError, match="clears"):
        BoardKind("k", (cnt, Register("clr", count=3, direction=OUTPUT, clears="cnt")))


def test_gripper_cage_names_the_cage_registers():
    """The cage's registers by name are the addresses of pyrt.boards.gripper; the DAC's off is
    its null; up/down are the encoder's pulse counters; the ports and LEDs power up high."""
    boards = open_boards("sim:", "gripper", {"gripper": GRIPPER_CAGE}).simulated
    view = boards.registers("gripper")
    board = GripperBoard(view)
    assert isinstance(view, RegisterBoard)
    view.write("led_lo", 0x5A)
    assert board.read(LED_LO) == 0x5A and GRIPPER_CAGE.register("led_lo").address == LED_LO
    view.write("dac", 0x90)
    assert board.read(DAC) == 0x90 and not outputs_are_off(GRIPPER_CAGE, view)
    outputs_off(GRIPPER_CAGE, view)
    assert board.read(DAC) == DAC_NULL
    view.set_input("up", 3)
    view.set_input("down", 1)
    assert view.snapshot() == [0xFF, 0xFF, 0xFF, 3, 1]
    assert view.read("up") == 3 and GRIPPER_CAGE.register("up").direction == INPUT
    assert view.read("led_hi") == 0xFF
