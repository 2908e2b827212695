"""Files as a door: damaged ``.dat`` lines and damaged or random journals, fuzzed (bounded).

A malformed database line is refused with its file and line named, by the
database reader and by a manipulator's start-up alike, and leaves every file
on disk as it was.  A damaged or random journal is refused with a reason by
the reader and by ``pyrt replay`` (never a traceback); bytes altered under a
frame's checksum are refused before any station is built (nothing replayed).
"""

from __future__ import annotations

import contextlib
import io
import re
import shutil
import zlib
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import pyrt.cli
from pyrt.db import FILES, copy_station, load_station
from pyrt.db._schema import SCHEMAS
from pyrt.errors import ConfigError
from pyrt.journal import JournalError, JournalReader
from pyrt.journal.format import FRAME_HEADER, HEADER_SIZE, KIND_HEADER, frame
from pyrt.station.manipulator import ManipulatorStation

JOURNALS = Path(__file__).resolve().parent / "journals"
DAT_FILES = sorted(FILES.values())

#: Bounded: these run in the default test run.
DAT_EXAMPLES = 150
JOURNAL_EXAMPLES = 200
REPLAY_EXAMPLES = 40

# -- .dat lines --------------------------------------------------------------------------

#: Pieces a malformed line is made of: the grammar's own words and characters, numbers
#: in other scripts, Python's extras, control and invisible characters.
_PIECES = [
    *"0123456789.+-eE:/;, \t", "//", "END;", "VERSION1.00", "AXIS:", "ENCODER:", "LENGTH:",
    "ZEROLENGTH:", "DEADLENGTH:", "POSITION:", "SLOPE:", "TOP:", "cm", "m", "mm", "kg", "N",
    "nan", "inf", "-0", "1_0", "0x1f", "1e999", "\u0663\u0660", "\u06f5", "\uff11",
    "\u00a0", "\u2009", "\x00", "\x1b[2J", "\u00e9", "\ufeff", "axis0", "encoder0",
]
_LINE = st.lists(st.sampled_from(_PIECES), max_size=12).map("".join)
#: Numbers as a value would hold them, their digits now and then another script's.
_DIGITS = st.lists(st.sampled_from([*"0123456789", "\u0663", "\u06f5", "\uff11", "\u0967"]),
                   min_size=1, max_size=6).map("".join)
_NUMBER = st.tuples(st.sampled_from(["", "-", "+"]), _DIGITS,
                    st.sampled_from(["", ".", ".5", "e1"]),
                    st.sampled_from(["", " cm", "m", " kg", " N"])).map("".join)
_VALUE = st.one_of(_LINE, st.text(max_size=20), _NUMBER,
                   st.lists(_NUMBER, min_size=3, max_size=3).map(" ".join))


@pytest.fixture(scope="module")
def prototype(tmp_path_factory) -> Path:
    """The packaged prototype station, copied once (each example copies it again)."""
    return copy_station("prototype", tmp_path_factory.mktemp("prototype"))


def _mutate(lines: list[str], kind: str, k: int, text: str) -> tuple[list[str], int]:
    """One line changed: the new lines and the 1-based line number changed."""
    k %= len(lines)
    out = list(lines)
    if kind == "replace":
        out[k] = text + "\n"
    elif kind == "insert":
        out.insert(k, text + "\n")
    elif kind == "value":
        # a 'KEY: value' line keeps its key, its value is replaced
        fields = [i for i, ln in enumerate(lines) if re.match(r"\s*[A-Z]+\s*:", ln)]
        k = fields[k % len(fields)]
        key, _, rest = lines[k].partition(":")
        comment = rest.partition("//")[2]
        out[k] = f"{key}: {text}" + (f" //{comment}" if comment else "\n")
    elif kind == "delete":
        del out[k]
    else:  # duplicate
        out.insert(k, lines[k])
    return out, k + 1


def _numeric(file: str, line: str) -> bool:
    """Whether ``line`` of ``file`` is a field holding numbers (not a name or text)."""
    key = line.partition(":")[0].strip().upper()
    spec = SCHEMAS[Path(file).stem.upper()].spec(key)
    return spec is not None and spec.kind not in ("name", "text")


def _names_file_and_line(exc: ConfigError, directory: Path) -> bool:
    return (exc.file is not None and Path(exc.file).parent == directory
            and Path(exc.file).name in DAT_FILES and exc.line is not None and exc.line >= 1)


@given(file=st.sampled_from(DAT_FILES),
       kind=st.sampled_from(["replace", "insert", "value", "delete", "duplicate"]),
       k=st.integers(0, 10_000), text=_VALUE)
@settings(max_examples=DAT_EXAMPLES, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_a_malformed_dat_line_is_refused_naming_file_and_line(prototype, tmp_path, file,
                                                              kind, k, text):
    """Any one line replaced, inserted, deleted, duplicated or given another value: the
    database loads, or is refused (ConfigError) naming one of its files and a line; a
    manipulator's start-up on it builds or is refused the same way; a refusal leaves
    every file byte for byte as it was."""
    d = tmp_path / "db"
    if d.exists():
        shutil.rmtree(d)
    shutil.copytree(prototype, d)
    path = d / file
    lines = path.read_text(encoding="utf-8").splitlines(keepends=True)
    new, _line = _mutate(lines, kind, k, text)
    path.write_bytes("".join(new).encode("utf-8", "surrogatepass"))
    before = {p.name: p.read_bytes() for p in d.glob("*.dat")}
    value = text.split("//", 1)[0]
    numeric = kind == "value" and _numeric(file, new[_line - 1])
    try:
        load_station(d)
    except ConfigError as exc:
        assert _names_file_and_line(exc, d), str(exc)
        if numeric:  # a malformed number is refused at its own line
            assert (Path(exc.file or "").name, exc.line) == (file, _line), str(exc)
    else:
        # numbers are ASCII digits only: a value written with others' digits is refused
        assert not (numeric and any(c.isdigit() and not c.isascii() for c in value)), \
            f"{file}:{_line}: {new[_line - 1]!r} was taken"
    try:
        station = ManipulatorStation(d, tick_ns=5_000_000)
    except ConfigError as exc:
        assert _names_file_and_line(exc, d), str(exc)
        after = {p.name: p.read_bytes() for p in d.glob("*.dat")}
        assert after == before
    else:
        station.close()


NON_ASCII_DIGITS = ["\u0663\u0660", "\u06f5", "\uff11\uff12", "1\u0660", "\u0967.5",
                    "\U0001d7d9"]


@pytest.mark.parametrize("digits", NON_ASCII_DIGITS)
@pytest.mark.parametrize("file, key", [("AXIS.dat", "DEADLENGTH"), ("ENCODER.dat", "ADDRESS"),
                                       ("ENCODER.dat", "ZEROLENGTH"),
                                       ("POLYAXIS.dat", "POSITION")])
def test_numbers_in_a_dat_file_are_ascii_digits_only(prototype, tmp_path, digits, file, key):
    """A number written with digits of another script (Arabic-Indic, fullwidth ...) is
    refused at its line, as any malformed number is; the file is unchanged."""
    d = shutil.copytree(prototype, tmp_path / "db")
    path = d / file
    lines = path.read_text(encoding="utf-8").splitlines(keepends=True)
    n = next(i for i, ln in enumerate(lines) if ln.startswith(f"{key}:"))
    value = f"{digits} 0 0" if key == "POSITION" else digits
    lines[n] = f"{key}: {value} // by hand\n"
    path.write_text("".join(lines), encoding="utf-8")
    before = path.read_bytes()
    with pytest.raises(ConfigError) as err:
        load_station(d)
    assert err.value.file == str(path) and err.value.line == n + 1
    assert path.read_bytes() == before


# -- journals ----------------------------------------------------------------------------


def _frames(data: bytes) -> list[tuple[bytes, bytes]]:
    """A sound journal's frames as (kind, payload)."""
    out, pos = [], 0
    while pos < len(data):
        _magic, kind, n, _crc = FRAME_HEADER.unpack_from(data, pos)
        out.append((kind, data[pos + HEADER_SIZE:pos + HEADER_SIZE + n]))
        pos += HEADER_SIZE + n
    return out


@pytest.fixture(scope="module")
def gripper_journal() -> bytes:
    return (JOURNALS / "gripper.pj").read_bytes()


def _damage(data: bytes, how: str, at: int, blob: bytes) -> bytes:
    """``data`` damaged at ``at`` (modulo its length) by ``how`` with ``blob``."""
    b = bytearray(data)
    at %= max(1, len(b))
    if how == "flip":
        b[at] ^= (blob[0] if blob and blob[0] else 1)
    elif how == "overwrite":
        b[at:at + len(blob)] = blob
        b = b[:len(data)] if len(b) > len(data) else b
    elif how == "insert":
        b[at:at] = blob or b"\0"
    elif how == "delete":
        del b[at:at + max(1, len(blob))]
    elif how == "random":
        b = bytearray(blob)
    return bytes(b)


def _reframed(data: bytes, which: int, at: int, blob: bytes) -> bytes:
    """Frame ``which``'s payload altered and framed again with a valid checksum (what a
    hand-made journal, or one from elsewhere, may hold): the reader's checks alone remain."""
    frames = _frames(data)
    i = which % len(frames)
    kind, payload = frames[i]
    p = bytearray(payload)
    if kind == b"Z" and p:  # a compressed block: alter what it holds, compress it again
        try:
            inner = bytearray(zlib.decompress(bytes(p)))
        except zlib.error:
            inner = bytearray(p)
        inner[at % max(1, len(inner)):at % max(1, len(inner)) + len(blob)] = blob
        p = bytearray(zlib.compress(bytes(inner)))
    else:
        k = at % max(1, len(p))
        p[k:k + len(blob)] = blob
    frames[i] = (kind, bytes(p))
    return b"".join(frame(k, pl) for k, pl in frames)


_HOW = st.sampled_from(["flip", "overwrite", "insert", "delete", "random"])


@given(how=_HOW, at=st.integers(0, 1 << 20), blob=st.binary(min_size=1, max_size=64))
@settings(max_examples=JOURNAL_EXAMPLES, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_a_damaged_journal_is_read_or_refused_with_a_reason(gripper_journal, how, at, blob):
    """Any byte damage (flip, overwrite, insertion, deletion, random bytes): the reader
    refuses with a JournalError naming where (never another exception), strict and
    salvaging alike, or reads what is intact."""
    data = _damage(gripper_journal, how, at, blob)
    for salvage in (False, True):
        try:
            reader = JournalReader(data, salvage=salvage)
            for _ in reader:
                pass
            reader.summary()
        except JournalError as exc:
            assert str(exc).startswith("journal ") and len(str(exc).splitlines()) == 1


@given(which=st.integers(0, 1000), at=st.integers(0, 1 << 20),
       blob=st.binary(min_size=1, max_size=16))
@settings(max_examples=JOURNAL_EXAMPLES, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_a_journal_altered_under_valid_checksums_is_refused_or_read(gripper_journal, which,
                                                                   at, blob):
    """A frame's payload altered and its checksum made valid again: the reader refuses
    with a JournalError (never another exception) or reads ticks it can decode."""
    data = _reframed(gripper_journal, which, at, blob)
    try:
        reader = JournalReader(data)
        for _ in reader:
            pass
        reader.summary()
    except JournalError as exc:
        assert str(exc).startswith("journal ") and len(str(exc).splitlines()) == 1


def _replay(path: Path) -> tuple[int, str, str, list[object]]:
    """``pyrt replay PATH`` in this process: status, stdout, stderr and the stations
    it built (none may be built for a journal it refuses)."""
    from pyrt.station import replay as replay_module

    built: list[object] = []
    attach = replay_module.Replay.attach

    def spy(self, station):
        built.append(station)
        return attach(self, station)

    out, err = io.StringIO(), io.StringIO()
    replay_module.Replay.attach = spy  # type: ignore[method-assign]
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            rc = pyrt.cli.main(["replay", str(path)])
    finally:
        replay_module.Replay.attach = attach  # type: ignore[method-assign]
    return rc, out.getvalue(), err.getvalue(), built


@given(how=_HOW, at=st.integers(0, 1 << 20), blob=st.binary(min_size=1, max_size=64),
       reframe=st.booleans(), which=st.integers(0, 1000))
@settings(max_examples=REPLAY_EXAMPLES, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_pyrt_replay_refuses_a_damaged_journal_with_one_line(gripper_journal, tmp_path, how,
                                                            at, blob, reframe, which):
    """``pyrt replay`` on a damaged journal: exit 1 with one line saying why and nothing
    built, or (bytes altered under valid checksums, or only cut short) a replay that ends
    with its verdict; never a traceback, never an internal error."""
    if reframe:
        data = _reframed(gripper_journal, which, at, blob)
    else:
        data = _damage(gripper_journal, how, at, blob)
    path = tmp_path / "damaged.pj"
    path.write_bytes(data)
    rc, out, err, built = _replay(path)
    assert "Traceback" not in out + err and "internal error" not in out + err
    assert rc in (0, 1)
    if rc == 1 and not built:
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("pyrt replay: "), err
    elif built:
        last = out.strip().splitlines()[-1] if out.strip() else err.strip()
        assert re.match(r"(replayed \d+ ticks|replay differs|pyrt replay: )", last) or \
            re.match(r"note: ", last), out + err
    if not reframe and data[:len(gripper_journal)] != gripper_journal and \
            gripper_journal[:len(data)] != data:
        # bytes altered (not only cut short or extended): the checksums refuse them
        assert rc == 1 and not built, out + err


_JSON = st.recursive(
    st.none() | st.booleans() | st.integers(-10**30, 10**30) | st.floats(allow_nan=False)
    | st.text(max_size=12) | st.sampled_from(["os:system", "builtins:exec", "../../etc",
                                              "tcp://127.0.0.1:9", "sim:", "gripper"]),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=5), inner,
                                                               max_size=3),
    max_leaves=6)


@pytest.fixture(scope="module")
def gripper_header(gripper_journal):
    from pyrt.journal.format import Header

    return Header.decode(_frames(gripper_journal)[0][1])


@given(where=st.sampled_from(["args", "top"]), key=st.data(), value=_JSON)
@settings(max_examples=REPLAY_EXAMPLES * 2, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_a_journal_header_from_elsewhere_is_refused_not_obeyed(gripper_journal, gripper_header,
                                                              tmp_path, where, key, value):
    """A journal whose header (sound checksums) carries settings pyrt never writes (a
    factory to import, an option of the wrong type, inputs that are not a list ...):
    ``pyrt replay`` refuses it in one line naming the setting, or replays it; never a
    traceback, never code named by the journal run."""
    import dataclasses
    import json

    meta = json.loads(json.dumps(dict(gripper_header.metadata)))
    if where == "args":
        name = key.draw(st.sampled_from(sorted(meta["args"])))
        meta["args"][name] = value
    else:
        name = key.draw(st.sampled_from(sorted(set(meta) - {"args"})))
        meta[name] = value
    header = dataclasses.replace(gripper_header, metadata=meta)
    frames = _frames(gripper_journal)
    path = tmp_path / "elsewhere.pj"
    path.write_bytes(frame(KIND_HEADER, header.encode())
                     + b"".join(frame(k, p) for k, p in frames[1:]))
    rc, out, err, built = _replay(path)
    assert "Traceback" not in out + err and "internal error" not in out + err
    assert rc in (0, 1), out + err
    if rc == 1 and not built:
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("pyrt replay: "), err


def test_a_journal_naming_code_outside_the_installed_stations_is_refused(gripper_journal,
                                                                        gripper_header,
                                                                        tmp_path):
    """A journal whose factory is MODULE:FACTORY of the journal's choosing: refused in a
    sentence that says how to confirm it (--factory), the module never imported."""
    import dataclasses
    import sys

    meta = dict(gripper_header.metadata, factory="pyrt_no_such_module_xyz:build")
    header = dataclasses.replace(gripper_header, metadata=meta)
    frames = _frames(gripper_journal)
    path = tmp_path / "code.pj"
    path.write_bytes(frame(KIND_HEADER, header.encode())
                     + b"".join(frame(k, p) for k, p in frames[1:]))
    rc, _out, err, built = _replay(path)
    assert rc == 1 and not built
    assert "pyrt_no_such_module_xyz:build" in err and "--factory" in err
    assert "cannot import" not in err and "pyrt_no_such_module_xyz" not in sys.modules


def test_an_option_whose_type_gives_a_tuple_is_still_replayed(tmp_path):
    """A journal pyrt wrote keeps replaying: the arm's --start Q0,Q1 (recorded as a list)
    is taken; the same option holding what its parser never gives is refused."""
    import dataclasses
    import json

    from pyrt.journal.format import Header

    frames = _frames((JOURNALS / "arm.pj").read_bytes())
    header = Header.decode(frames[0][1])
    for start, replayed in (([10.0, 20.0], True), ([1], False), ("x", False)):
        meta = json.loads(json.dumps(dict(header.metadata)))
        meta["args"]["start"] = start
        path = tmp_path / "arm.pj"
        path.write_bytes(frame(KIND_HEADER, dataclasses.replace(header, metadata=meta).encode())
                         + b"".join(frame(k, p) for k, p in frames[1:]))
        rc, out, err, built = _replay(path)
        if replayed:
            assert rc == 0 and built and out.strip().endswith("identical"), out + err
        else:
            assert rc == 1 and not built and "its run's option start is" in err


def test_a_random_file_is_not_a_journal(tmp_path):
    """Random bytes, an empty file and a text file: refused in one line, nothing built."""
    for name, data in [("random.pj", bytes(range(256)) * 8), ("empty.pj", b""),
                       ("text.pj", b"VERSION1.00\nAXIS: a\nEND;\n")]:
        p = tmp_path / name
        p.write_bytes(data)
        rc, out, err, built = _replay(p)
        assert rc == 1 and not built and out == ""
        assert len(err.strip().splitlines()) == 1 and err.startswith("pyrt replay: ")


def test_the_kept_journal_frames_parse(gripper_journal):
    """The helper's frame split matches the file (a header frame first)."""
    frames = _frames(gripper_journal)
    assert frames[0][0] == KIND_HEADER
    assert b"".join(frame(k, p) for k, p in frames) == gripper_journal
