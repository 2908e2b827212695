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
    Access,
    WireError,
    greeting_line,
    parse_greeting,
    parse_request,
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
    (b"QUIT now", "syntax", "takes no arguments"),
    (b"R servo \xe9", "ascii", "ASCII"),
])
def test_malformed_requests_get_the_protocols_error(line, code, text):
    """Each malformed or out-of-range request is a WireError with its code and a clear text."""
    with pytest.raises(WireError) as err:
        parse_request(line, KINDS)
    assert err.value.code == code and text in err.value.text


_TOKENS = st.sampled_from([
    "R", "W", "SNAP", "INFO", "QUIT", "r", "w", "snap", "servo", "SERVO", "gripper", "tio10",
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
