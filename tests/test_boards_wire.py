"""The wire protocol's request and greeting parsers: what they accept, and (by property) that
anything else is refused with the protocol's own error, never another exception."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyrt.boards.kinds import DATACONCENTRATOR, GRIPPER_CAGE, TIO10_KIND
from pyrt.boards.registers import OUTPUT, BoardKind, Register
from pyrt.boards.wire import (
    MAX_LINE,
    MAX_STREAM_MS,
    PUSH,
    Access,
    WireError,
    greeting_line,
    parse_greeting,
    parse_request,
    snapshot_line,
    snapshot_struct,
)

SERVO = BoardKind("arm-servo", (
    Register("drive", count=2, width=16, signed=True, direction=OUTPUT, off=0),
    Register("count", count=2, width=32, signed=True),
    Register("strobe", direction=OUTPUT, readback=False),
))
KINDS = {"servo": SERVO, "gripper": GRIPPER_CAGE, "tio10": TIO10_KIND, "dc": DATACONCENTRATOR}


def test_reads_writes_and_snaps_parse_into_accesses():
    """R and W name a board, a register and an index (0 if not given); several writes share a
    line; SNAP may name boards; verbs and names in any case."""
    assert parse_request(b"R servo count 1", KINDS).accesses == (Access("servo", "count", 1),)
    assert parse_request(b"r SERVO Drive\r", KINDS).accesses == (Access("servo", "drive", 0),)
    req = parse_request(b"W servo drive 1 -0x10; w servo drive 5 ;W tio10 armed 7 1", KINDS)
    assert req.verb == "W" and req.accesses == (
        Access("servo", "drive", 1, -16), Access("servo", "drive", 0, 5),
        Access("tio10", "armed", 7, 1))
    assert parse_request(b"SNAP", KINDS).boards == ()
    assert parse_request(b"snap dc servo", KINDS).boards == ("dc", "servo")
    assert parse_request(b"INFO", KINDS).verb == "INFO"
    assert parse_request(b"QUIT\n", KINDS).verb == "QUIT"
    assert Access("servo", "drive", 1, -16).line() == "W servo drive 1 -16"


def test_the_packed_requests_parse_with_their_boards_and_milliseconds():
    """SNAPX names boards as SNAP does; STREAM takes its milliseconds (0 stops) and boards."""
    assert parse_request(b"SNAPX", KINDS) == parse_request(b"snapx", KINDS)
    assert parse_request(b"SNAPX dc servo", KINDS).boards == ("dc", "servo")
    req = parse_request(b"stream 100 gripper", KINDS)
    assert (req.verb, req.ms, req.boards) == ("STREAM", 100, ("gripper",))
    assert parse_request(b"STREAM 0", KINDS).ms == 0
    assert parse_request(f"STREAM {MAX_STREAM_MS}".encode(), KINDS).ms == MAX_STREAM_MS


def test_the_packed_layout_is_four_bytes_per_input_signed_as_declared():
    """TRIPS then every input in SNAP's order, four bytes each, little-endian, signed where
    the register is: the servo's two signed counts, the gripper's five unsigned inputs."""
    assert snapshot_struct(KINDS, ("servo",)).format == "<Iii"
    assert snapshot_struct(KINDS, ("gripper",)).format == "<IIIIII"
    assert snapshot_struct(KINDS).size == 4 * (1 + 2 + 5 + 11 + 272)
    assert snapshot_line(snapshot_struct(KINDS, ("servo",)), 1, [-1, 2]) == \
        b"OK 01000000ffffffff02000000\n"
    assert snapshot_line(snapshot_struct(KINDS, ("servo",)), 2**32 + 3, [0, 0], PUSH) == \
        b"S 030000000000000000000000\n"


def _inputs(kinds: dict[str, BoardKind]) -> st.SearchStrategy[list[int]]:
    """Every input of ``kinds`` in SNAP's order, each anywhere in its register's range."""
    regs = [reg for kind in kinds.values() for reg in kind.inputs() for _ in range(reg.count)]
    return st.tuples(*(st.integers(reg.low, reg.high) for reg in regs)).map(list)


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2**32 - 1), _inputs({"servo": SERVO, "gripper": GRIPPER_CAGE,
                                            "tio10": TIO10_KIND}))
def test_a_packed_snapshot_reads_back_every_value_as_snap_gives_it(trips, values):
    """Packing then unpacking the hexadecimal gives back TRIPS and every input, whatever its
    width and sign (the SNAPX reply and a push carry exactly SNAP's numbers)."""
    kinds = {"servo": SERVO, "gripper": GRIPPER_CAGE, "tio10": TIO10_KIND}
    layout = snapshot_struct(kinds)
    line = snapshot_line(layout, trips, values)
    assert line.startswith(b"OK ") and line.endswith(b"\n") and line.isascii()
    assert list(layout.unpack(bytes.fromhex(line[3:-1].decode()))) == [trips, *values]


@pytest.mark.parametrize(("line", "code", "text"), [
    (b"", "syntax", "empty request"),
    (b"PEEK 1", "syntax", "unknown request"),
    (b"R servo", "syntax", "R takes 2 or 3 arguments"),
    (b"W servo drive 1 2 3", "syntax", "W takes 3 or 4 arguments"),
    (b"R servo drive x", "syntax", "is not a number"),
    (b"R servo drive --1", "syntax", "is not a number"),
    (b"R servo drive 1" + b"0" * 30, "syntax", "is not a number"),
    (b"R arm drive", "range", "no board 'arm'; boards: servo gripper tio10 dc"),
    (b"R servo speed", "range", "no register 'speed'"),
    (b"R servo drive 2", "range", "index must be 0..1"),
    (b"W servo drive 0 32768", "range", "-32768..32767"),
    (b"W servo count 0 1", "range", "count is an input"),
    (b"R servo strobe", "range", "write-only"),
    (b"R dc clr 3", "range", "write-only"),
    (b"W servo drive 1; R servo drive", "syntax", "only writes"),
    (b"SNAP servo servo", "syntax", "names a board twice"),
    (b"SNAPX dc dc", "syntax", "SNAPX names a board twice"),
    (b"SNAPX arm", "range", "no board 'arm'"),
    (b"STREAM", "syntax", "STREAM takes the milliseconds"),
    (b"STREAM x", "syntax", "is not a number"),
    (b"STREAM -1", "range", f"0..{MAX_STREAM_MS} ms"),
    (b"STREAM 10001", "range", f"0..{MAX_STREAM_MS} ms"),
    (b"STREAM 100 servo arm", "range", "no board 'arm'"),
    (b"QUIT now", "syntax", "takes no arguments"),
    (b"R servo \xe9", "ascii", "ASCII"),
])
def test_malformed_requests_get_the_protocols_error(line, code, text):
    """Each malformed or out-of-range request is a WireError with its code and a clear text."""
    with pytest.raises(WireError) as err:
        parse_request(line, KINDS)
    assert err.value.code == code and text in err.value.text


_TOKENS = st.sampled_from([
    "R", "W", "SNAP", "SNAPX", "STREAM", "INFO", "QUIT", "r", "w", "snap", "stream", "servo", "SERVO", "gripper", "tio10",
    "dc", "drive", "count", "strobe", "dac", "pa", "armed", "cnt", "clr", "0", "1", "-1", "7",
    "255", "256", "0x", "0xFF", "-0x8000", "32768", "-32769", "99999999999999999999999", "1e3",
    ";", "; W", "--", "\t", "\x00", "\x1f", "é", "R;W", "=", "",
])


@settings(max_examples=400, deadline=None)
@given(st.lists(_TOKENS, max_size=12), st.sampled_from([" ", "  ", "\t", ";", " ; "]))
def test_request_parser_never_raises_anything_but_wire_errors(tokens, sep):
    """Any line made of protocol-like tokens parses to a request whose accesses fit the
    declarations, or is refused with WireError: never another exception."""
    line = sep.join(tokens).encode("utf-8")
    try:
        req = parse_request(line, KINDS)
    except WireError as exc:
        assert exc.code in ("syntax", "range", "ascii")
        return
    for a in req.accesses:
        reg = KINDS[a.board].register(a.register)
        assert 0 <= a.index < reg.count
        assert a.value is None or reg.fits(a.value)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=MAX_LINE))
def test_request_parser_refuses_arbitrary_bytes_with_wire_errors_only(data):
    """Arbitrary bytes never raise anything but WireError."""
    try:
        parse_request(data, KINDS)
    except WireError as exc:
        assert exc.code in ("syntax", "range", "ascii")


@settings(max_examples=200, deadline=None)
@given(st.text(max_size=200))
def test_greeting_parser_refuses_anything_else_with_wire_errors_only(text):
    """A greeting that is not one is a WireError, never another exception."""
    try:
        parse_greeting(text)
    except WireError as exc:
        assert exc.code == "syntax"


def test_greeting_round_trips_and_names_what_is_wrong():
    """greeting_line and parse_greeting agree; another version or another server is named."""
    line = greeting_line("arm", 500, {"servo": SERVO, "gripper": GRIPPER_CAGE}).decode()
    g = parse_greeting(line)
    assert (g.station, g.watchdog_ms) == ("arm", 500)
    assert g.boards == {"servo": SERVO.tag, "gripper": GRIPPER_CAGE.tag}
    with pytest.raises(WireError, match="another protocol version"):
        parse_greeting("OK pyrt-board-sim 1 gripper gripper 500")
    with pytest.raises(WireError, match="not a pyrt board-sim"):
        parse_greeting("SSH-2.0-OpenSSH_9.6")
    with pytest.raises(WireError, match="malformed board"):
        parse_greeting("OK pyrt-board-sim 2 arm 500 servo")
