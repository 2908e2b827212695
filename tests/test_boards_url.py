"""Board URLs and the back-end registry: parsing, built-in schemes, entry points, refusals."""

from __future__ import annotations

import importlib.metadata

import pytest

from pyrt.boards import (
    DEFAULT_URL,
    ENTRY_POINT_GROUP,
    Boards,
    BoardURL,
    known_schemes,
    open_boards,
    parse_board_url,
    register_backend,
)
from pyrt.boards import registry as registry_module
from pyrt.boards.dataconcentrator import DataConcentrator
from pyrt.boards.gripper import DAC, P8155_PA, P8155_PB, GripperBoard
from pyrt.boards.i8031 import I8031
from pyrt.boards.registers import OUTPUT, BoardKind, Register, RegisterBoard
from pyrt.boards.tio10 import TIO10
from pyrt.errors import ConfigError
from pyrt.sim.world import GRIPPER_BOARDS, MANIPULATOR_BOARDS

# -- a third party's back end, found through an entry point ---------------------------

CALLS: list[tuple[BoardURL, str, dict]] = []


def fake_factory(url: BoardURL, station: str, kinds: dict, **options) -> Boards:
    """A back end of 'someone else': in-process boards, remembering how it was called."""
    CALLS.append((url, station, options))
    boards = {name: kind.sim(**({"cpu": options["cpu"]} if "cpu" in options else {}))
              for name, kind in kinds.items()}
    return Boards(url.text, station, boards, kinds, in_process=True, world="fake")


def not_boards(url: BoardURL, station: str, kinds: dict, **options) -> object:
    """A broken back end: returns something that is not Boards."""
    return object()


@pytest.fixture
def entry_points(monkeypatch):
    """Install entry points of the pyrt.boards group (name -> 'module:attr')."""

    def install(table: dict[str, str]) -> None:
        eps = [importlib.metadata.EntryPoint(name, value, ENTRY_POINT_GROUP)
               for name, value in table.items()]

        def fake(**kw):
            assert kw == {"group": ENTRY_POINT_GROUP}
            return importlib.metadata.EntryPoints(eps)

        monkeypatch.setattr(importlib.metadata, "entry_points", fake)

    CALLS.clear()
    return install


# -- parsing ----------------------------------------------------------------------------


def test_sim_url_is_the_scheme_alone_and_the_default():
    """'sim:' parses to scheme sim with no host, port, path or options; it is the default URL."""
    u = parse_board_url("sim:")
    assert (u.scheme, u.host, u.port, u.path, u.options) == ("sim", "", None, "", {})
    assert DEFAULT_URL == "sim:"
    assert parse_board_url("SIM:").scheme == "sim"


@pytest.mark.parametrize(("url", "host", "port", "options"), [
    ("tcp://127.0.0.1:5055", "127.0.0.1", 5055, {}),
    ("tcp://localhost:1?timeout=0.5&max_age=0", "localhost", 1, {"timeout": "0.5", "max_age": "0"}),
    ("TCP://[::1]:80/", "::1", 80, {}),
])
def test_tcp_url_gives_host_port_and_options(url, host, port, options):
    """tcp://HOST:PORT?K=V parses host (IPv6 in brackets), port and the query's options."""
    u = parse_board_url(url)
    assert (u.scheme, u.host, u.port, u.options, u.text) == ("tcp", host, port, options, url)


@pytest.mark.parametrize("url", [
    "", " sim:", "sim: ", "5055", "127.0.0.1:5055:x", "tcp://h:99999",
    "tcp://h:port", "tcp://h:1?timeout", "tcp://h:1?a=1&a=2", "tcp://h:1#frag", "tcp://u:p@h:1",
    "t cp://h:1", "sim:\n",
])
def test_malformed_url_is_a_config_error_naming_it_and_the_known_schemes(url):
    """A malformed URL raises ConfigError that names the URL and lists sim and tcp."""
    with pytest.raises(ConfigError) as err:
        open_boards(url, "gripper", GRIPPER_BOARDS)
    text = str(err.value)
    assert repr(url) in text
    assert "sim" in text and "tcp" in text


def test_unknown_scheme_is_a_config_error_naming_the_url_and_the_known_schemes(entry_points):
    """open_boards('serial:///dev/ttyS0') names the URL, the scheme and every known scheme."""
    entry_points({})
    with pytest.raises(ConfigError) as err:
        open_boards("serial:///dev/ttyS0", "prototype", MANIPULATOR_BOARDS)
    text = str(err.value)
    assert "'serial:///dev/ttyS0'" in text and "'serial'" in text
    assert "known schemes: modbus, sim, tcp" in text


def test_board_url_that_is_not_text_is_refused():
    """A URL that is not a string is a ConfigError, not a TypeError."""
    with pytest.raises(ConfigError, match="must be text"):
        parse_board_url(5055)  # type: ignore[arg-type]


# -- sim: ------------------------------------------------------------------------------


def test_sim_gripper_maps_the_cage_into_the_given_cpu_over_a_simulated_board():
    """sim: for the gripper gives the cage mapped into the cpu passed, reached through the
    process image; the world's side is the cage's register file, which a write reaches at
    once outside a tick and the read phase brings in."""
    cpu = I8031()
    with open_boards("sim:", "gripper", GRIPPER_BOARDS, cpu=cpu) as boards:
        assert boards.in_process and boards["gripper"].cpu is cpu and boards.station == "gripper"
        assert list(boards) == ["gripper"] and len(boards) == 1
        assert isinstance(boards["gripper"], GripperBoard)
        side = boards.simulated
        assert side is not None and isinstance(side["gripper"], RegisterBoard)
        cpu.movx_write(DAC, 0x90)
        assert side["gripper"].output("dac") == 0x90 and boards["gripper"].read(DAC) == 0x90
        side["gripper"].set_input("pa", 0xFE)
        boards.poll(0)
        assert cpu.movx_read(P8155_PA) == 0xFE
    assert boards.closed


def test_sim_manipulator_gives_a_sim_tio10_and_dataconcentrator():
    """sim: (also by default) for the manipulator gives a TIO10 and a dataConcentrator over the
    image of the two cards' register files."""
    boards = open_boards(None, "prototype", MANIPULATOR_BOARDS)
    assert boards.url == "sim:" and boards.in_process
    side = boards.simulated
    assert side is not None
    assert side["tio10"].kind.name == "tio10" and side["dc"].kind.name == "dataconcentrator"
    assert isinstance(boards["tio10"], TIO10) and isinstance(boards["dc"], DataConcentrator)
    assert list(boards) == ["tio10", "dc"] and "gripper" not in boards
    with pytest.raises(KeyError, match="tio10, dc"):
        boards["gripper"]
    boards.close()
    boards.close()  # idempotent


def test_sim_gripper_without_a_cpu_makes_one():
    """sim: for the gripper without cpu= makes a new 8031 and maps the board into it."""
    boards = open_boards("sim:", "gripper", GRIPPER_BOARDS)
    assert isinstance(boards["gripper"].cpu, I8031)
    assert boards["gripper"].cpu.movx_read(P8155_PB) == 0xFF


@pytest.mark.parametrize("url", ["sim://host:1", "sim:/path", "sim:?speed=2"])
def test_sim_refuses_a_host_a_path_or_options(url):
    """sim: takes nothing after the colon: ConfigError naming the URL."""
    with pytest.raises(ConfigError, match="sim:"):
        open_boards(url, "gripper", GRIPPER_BOARDS)


def test_sim_refuses_an_unknown_keyword_option():
    """A keyword option sim: does not take is refused by name."""
    with pytest.raises(ConfigError, match="timeout"):
        open_boards("sim:", "prototype", MANIPULATOR_BOARDS, timeout=1)


def test_any_station_opens_its_declared_boards_and_a_bad_declaration_is_refused():
    """open_boards knows no list of robots: a hexapod's own kind opens (a RegisterBoard in
    process); a declaration that is not a mapping of names to kinds is a ConfigError."""
    leg = BoardKind("hexapod-leg", (Register("angle", count=3, width=12, direction=OUTPUT),))
    with open_boards("sim:", "hexapod", {"leg0": leg, "leg1": leg}) as boards:
        assert isinstance(boards.simulated["leg1"], RegisterBoard)
        assert boards["leg1"].kind is leg
        assert boards["leg0"] is not boards["leg1"] and boards.registers("leg0") is boards["leg0"]
    for bad in ({}, {"Leg": leg}, {"leg": "hexapod-leg"}, ["leg"]):
        with pytest.raises(ConfigError):
            open_boards("sim:", "hexapod", bad)
    with pytest.raises(ConfigError, match="one ASCII word"):
        open_boards("sim:", "hexa pod", {"leg": leg})


def test_tcp_refuses_unknown_options_and_bad_seconds_before_connecting():
    """tcp: names an unknown option, a bad timeout, a missing or zero port, without connecting."""
    with pytest.raises(ConfigError, match="speed"):
        open_boards("tcp://127.0.0.1:9?speed=2", "gripper", GRIPPER_BOARDS)
    with pytest.raises(ConfigError, match="timeout"):
        open_boards("tcp://127.0.0.1:9?timeout=soon", "gripper", GRIPPER_BOARDS)
    with pytest.raises(ConfigError, match="timeout"):
        open_boards("tcp://127.0.0.1:9", "gripper", GRIPPER_BOARDS, timeout=0)
    with pytest.raises(ConfigError, match="port"):
        open_boards("tcp://127.0.0.1", "gripper", GRIPPER_BOARDS)
    with pytest.raises(ConfigError, match="host"):
        open_boards("tcp://:5055", "gripper", GRIPPER_BOARDS)
    with pytest.raises(ConfigError, match="port"):
        open_boards("tcp://127.0.0.1:0", "gripper", GRIPPER_BOARDS)
    with pytest.raises(ConfigError, match="path"):
        open_boards("tcp://127.0.0.1:9/x", "gripper", GRIPPER_BOARDS)


# -- the registry ---------------------------------------------------------------------------


def test_entry_point_back_end_is_found_by_scheme_with_its_options(entry_points):
    """A scheme registered in the pyrt.boards entry-point group opens through open_boards; URL
    options and keyword options (which win) reach the factory."""
    entry_points({"fake": f"{__name__}:fake_factory"})
    assert known_schemes() == ["fake", "modbus", "sim", "tcp"]
    boards = open_boards("FAKE://lab-rack:7?gain=2&mode=a", "prototype", MANIPULATOR_BOARDS, mode="b")
    assert boards.world == "fake" and isinstance(boards["tio10"], RegisterBoard)
    url, station, options = CALLS[-1]
    assert (url.scheme, url.host, url.port, station) == ("fake", "lab-rack", 7, "prototype")
    assert options == {"gain": "2", "mode": "b"}


def test_entry_point_that_cannot_be_loaded_is_a_config_error_naming_it(entry_points):
    """An entry point whose module is missing is a ConfigError naming the scheme and the entry point."""
    entry_points({"ghost": "no_such_module_anywhere:open"})
    with pytest.raises(ConfigError) as err:
        open_boards("ghost:", "gripper", GRIPPER_BOARDS)
    assert "'ghost'" in str(err.value) and "no_such_module_anywhere:open" in str(err.value)


def test_factory_that_returns_no_boards_is_refused(entry_points):
    """A factory that returns something other than Boards is a ConfigError naming the scheme."""
    entry_points({"broken": f"{__name__}:not_boards"})
    with pytest.raises(ConfigError, match="'broken' returned object, not Boards"):
        open_boards("broken:", "gripper", GRIPPER_BOARDS)


def test_entry_point_cannot_replace_a_built_in_scheme(entry_points):
    """An entry point named 'sim' does not replace the built-in sim: back end."""
    entry_points({"sim": f"{__name__}:fake_factory"})
    boards = open_boards("sim:", "prototype", MANIPULATOR_BOARDS)
    assert boards.world == "sim" and not CALLS


def test_register_backend_from_code(monkeypatch, entry_points):
    """register_backend adds a scheme from code; a built-in scheme cannot be registered."""
    entry_points({})
    monkeypatch.setattr(registry_module, "_registered", {})
    register_backend("Bench", fake_factory)
    assert "bench" in known_schemes()
    assert open_boards("bench:", "gripper", GRIPPER_BOARDS).world == "fake"
    with pytest.raises(ConfigError, match="built in"):
        register_backend("tcp", fake_factory)
    with pytest.raises(ConfigError, match="not a URL scheme"):
        register_backend("9lives", fake_factory)


def test_boards_must_hold_every_declared_board():
    """Boards without a declared board (the gripper's cage, the manipulator's dataConcentrator)
    is refused, naming the missing board."""
    with pytest.raises(ConfigError, match="no gripper board"):
        Boards("x:", "gripper", {}, GRIPPER_BOARDS, in_process=True)
    with pytest.raises(ConfigError, match="no dc board"):
        Boards("x:", "prototype", {"tio10": RegisterBoard(MANIPULATOR_BOARDS["tio10"])}, MANIPULATOR_BOARDS, in_process=True)


def test_read_inputs_reads_the_image_without_stepping_the_world():
    """Boards.read_inputs (a station being built) brings the inputs in without the world's
    step; the read phase (poll) steps it first, then reads."""
    boards = open_boards("sim:", "gripper", GRIPPER_BOARDS)
    steps: list[int] = []
    side = boards.simulated
    assert side is not None and boards.attach_world(steps.append)
    boards.set_tick(0.001)
    side["gripper"].set_input("pa", 0x7F)
    boards.read_inputs(5)
    assert steps == [] and boards["gripper"].read(P8155_PA) == 0x7F
    side["gripper"].set_input("pa", 0x3F)
    boards.poll(6)
    assert steps == [6] and boards["gripper"].read(P8155_PA) == 0x3F
    boards.close()


def test_a_bound_write_refuses_what_write_refuses_and_a_same_value_is_no_change():
    """A register bound once (ImageBackend.writer) refuses a value the declaration does not
    hold, as write() does, leaving the image as it was; writing the value it holds is not a
    change (the write phase sends nothing, the tap sees nothing)."""
    boards = open_boards("sim:", "gripper", GRIPPER_BOARDS)
    image = boards.image
    seen: list[tuple[int, int]] = []

    class Tap:
        def wrote(self, slot: int, value: int) -> None:
            seen.append((slot, value))

    image.tap = Tap()
    boards.set_tick(0.001)
    write = image.writer("gripper", "dac")
    boards.poll(0)
    for bad in (0x100, -1, True, 1.5, "80"):
        with pytest.raises(ValueError, match="dac"):
            write(bad)
    assert image.read("gripper", "dac") == 0x80 and seen == []
    write(0x80)  # the value it holds: no change
    assert seen == []
    write(0x90)
    assert seen == [(image.output_index[("gripper", "dac", 0)], 0x90)]
    assert boards.simulated["gripper"].output("dac") == 0x80  # in the image until the write phase
    boards.flush(0)
    assert boards.simulated["gripper"].output("dac") == 0x90
    with pytest.raises(ValueError, match="input"):
        image.writer("gripper", "pa")
    boards.close()
