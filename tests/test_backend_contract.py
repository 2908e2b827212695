"""The back-end contract (pyrt.boards.backend, pyrt.boards.image) passed by every back end:
sim:, tcp://, modbus://, and one of one's own (``own:``, registered from code).

Each back end opens the gripper cage of a GripperWorld (in process for sim:, served by a
BoardServer or a ModbusBoardServer in a thread for tcp:// and modbus://, a link of its own
for own:).  To add a back end of one's own, add a fixture branch that opens it and drops
its link.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import pytest

from pyrt.boards import Boards, open_boards
from pyrt.boards.gripper import DAC_NULL
from pyrt.boards.image import MIN_TIMEOUT_S, ImageBackend, ImageRegisters, Write
from pyrt.boards.modbus import builtin_map
from pyrt.boards.modbusmap import load_map
from pyrt.boards.registers import Registers
from pyrt.boards.registry import BoardURL, register_backend, unregister_backend
from pyrt.errors import BoardError
from pyrt.sim.boardsim import BoardServer
from pyrt.sim.modbusserver import ModbusBoardServer
from pyrt.sim.world import GRIPPER_BOARDS, GripperWorld

BACKENDS = ["sim", "tcp", "modbus", "own"]


class OwnLink(ImageBackend):
    """A back end of one's own: the protocol implemented by an image whose exchanges reach
    a world's registers directly (as a driver of a bus would), with a link that can drop."""

    def __init__(self, url: str, world: GripperWorld):
        super().__init__(url, GRIPPER_BOARDS, max_age=0)
        self.far = world.registers("gripper")
        self.dropped: str | None = None

    def exchange_inputs(self) -> list[int]:
        self._check()
        return self.far.snapshot()

    def exchange_outputs(self, writes: list[Write]) -> None:
        self._check()
        for _b, n, i, v in writes:
            self.far.write(n, v, i)

    exchange_outputs_now = exchange_outputs

    def read_outputs(self) -> dict[tuple[str, str, int], int]:
        return {("gripper", r.name, 0): self.far.read(r.name)
                for r in GRIPPER_BOARDS["gripper"].outputs()}

    def _check(self) -> None:
        if self.dropped is not None:
            raise BoardError(self.url, f"the link is down ({self.dropped})")

    @property
    def down(self) -> str | None:
        return self.dropped

    def close_link(self) -> None:
        self.dropped = self.dropped or "closed"


def open_own(url: BoardURL, station: str, kinds: dict, *, world: GripperWorld) -> Boards:
    """The factory of own: (what an entry point in group pyrt.boards names)."""
    link = OwnLink(url.text, world)
    link.open()
    views = {name: ImageRegisters(link, name) for name in kinds}
    boards = {name: kind.remote(views[name]) for name, kind in kinds.items()}
    link.after_read.extend(b.poll for b in boards.values())
    return Boards(url.text, station, boards, kinds, link, views=views)


@dataclass
class Rig:
    """One back end's boards and the far side's register view of them."""

    scheme: str
    boards: Boards
    far: Registers
    drop: Callable[[], None]

    @property
    def view(self) -> Registers:
        return self.boards.registers("gripper")


@pytest.fixture(params=BACKENDS)
def rig(request) -> Iterator[Rig]:
    scheme = request.param
    if scheme == "sim":
        boards = open_boards("sim:", "gripper", GRIPPER_BOARDS)
        world = GripperWorld(start=-0x100, boards=boards)  # the world's side of sim:
        yield Rig(scheme, boards, world.registers("gripper"), lambda: None)
        boards.close()
        return
    world = GripperWorld(start=-0x100)
    if scheme == "own":
        register_backend("own", open_own)
        try:
            boards = open_boards("own:", "gripper", GRIPPER_BOARDS, world=world)

            def drop() -> None:
                boards.backend.dropped = "unplugged"

            yield Rig(scheme, boards, world.registers("gripper"), drop)
            boards.close()
        finally:
            unregister_backend("own")
        return
    if scheme == "tcp":
        server = BoardServer(world, "127.0.0.1", 0, watchdog_s=30.0)
        server.start()
        url = server.url
    else:
        server = ModbusBoardServer(world, load_map(builtin_map("gripper"), GRIPPER_BOARDS),
                                   watchdog_s=30.0)
        server.start()
        url = f"{server.url}?map=builtin:gripper"
    boards = open_boards(url, "gripper", GRIPPER_BOARDS, max_age=0)
    try:
        yield Rig(scheme, boards, world.registers("gripper"), server.close)
    finally:
        boards.close()
        server.close()


def test_open_gives_every_declared_board_and_its_url(rig):
    """Open: a Boards holding every declared board, saying its URL; in process only for sim:."""
    assert list(rig.boards) == ["gripper"]
    assert rig.boards.in_process == (rig.scheme == "sim")
    assert rig.boards.url.startswith(f"{rig.scheme}:")
    assert rig.boards.down is None


def test_the_read_phase_brings_the_inputs_into_the_image(rig):
    """Read inputs: what the far side holds is read in the read phase, and a read in the tick
    answers from the image (the far side's change after the read phase is not seen)."""
    before = rig.far.read("up")
    rig.boards.set_tick(0.001)
    rig.boards.poll(0)
    assert rig.view.read("up") == before
    assert [rig.view.read(n) for n in ("pa", "pb", "pc")] == \
        [rig.far.read(n) for n in ("pa", "pb", "pc")]
    rig.boards.flush(0)


def test_the_write_phase_sends_the_outputs_the_tick_changed(rig):
    """Write outputs: in a tick a write is in the image at once and at the far side after the
    write phase (in process too: one tick shape); outside a tick it goes out at once."""
    rig.boards.set_tick(0.001)
    rig.boards.poll(0)
    rig.view.write("dac", 0x90)
    assert rig.view.read("dac") == 0x90
    assert rig.far.read("dac") == DAC_NULL
    rig.boards.flush(0)
    rig.boards.poll(0)  # the pipelined reply is read here
    assert rig.far.read("dac") == 0x90
    rig.boards.flush(0)
    rig.view.write("led_lo", 0x01)
    assert rig.far.read("led_lo") == 0x01


def test_the_reflex_writes_at_once_and_a_dead_link_records_it_as_failed(rig):
    """Reflex: write_now sends the tick's writes at once; on a dropped link the off writes
    succeed where the far side turns its outputs off (board-sim over tcp) and raise BoardError
    naming the URL otherwise (modbus:// does not assume it)."""
    rig.boards.set_tick(0.001)
    rig.boards.poll(0)
    rig.view.write("dac", 0x90)
    rig.boards.write_now()
    assert rig.far.read("dac") == 0x90
    rig.boards.flush(0)
    rig.drop()
    if rig.scheme != "sim":
        with pytest.raises(BoardError):  # a reply already in before the drop may be read
            for _ in range(3):
                rig.boards.poll(0)
                rig.boards.flush(0)
        assert rig.boards.down is not None
    if rig.scheme in ("modbus", "own"):  # the far side is not assumed to turn them off
        with pytest.raises(BoardError, match="link is down") as err:
            rig.view.write("dac", DAC_NULL)
        assert err.value.url == rig.boards.url
    else:
        rig.view.write("dac", DAC_NULL)
        rig.boards.write_now()
        assert rig.view.read("dac") == DAC_NULL
    if rig.scheme != "sim":
        with pytest.raises(BoardError, match="link is down"):
            rig.view.write("dac", 0x90)


def test_the_timeout_is_derived_from_the_tick(rig):
    """Timeout: N x M ticks, never below the floor; a fixed timeout option is not derived."""
    rig.boards.set_tick(0.01)
    if rig.scheme == "sim":
        return  # nothing to wait for in process
    backend = rig.view.client
    assert backend.overrun_ns == backend.overrun_ticks * 10_000_000
    assert backend.timeout_s == pytest.approx(
        max(MIN_TIMEOUT_S, backend.overrun_ticks * backend.overrun_limit * 0.01))


def test_m_late_replies_in_a_row_trip_naming_the_url(rig):
    """Overruns: with a tick far shorter than a reply (1 µs), N=1 and M=3, every exchange is
    an overrun and the third in a row raises BoardError naming the URL."""
    if rig.scheme == "sim":
        rig.boards.set_tick(1e-6)
        for _ in range(5):
            rig.boards.poll(0)  # in process: no link, never late
        return
    if rig.scheme == "own":
        return  # its link is in this process: how late a reply is, is the machine's
    backend = rig.view.client
    backend.overrun_ticks, backend.overrun_limit = 1, 3
    rig.boards.set_tick(1e-6)
    rig.boards.poll(0)
    rig.boards.poll(0)
    assert backend.overruns == 2
    with pytest.raises(BoardError, match="3 replies in a row later than 1 ticks") as err:
        rig.boards.poll(0)
    assert err.value.url == rig.boards.url


def test_a_lost_link_raises_naming_the_url_and_stays_down(rig):
    """Lost link: the next exchange raises BoardError naming the URL, and every later one."""
    if rig.scheme == "sim":
        return
    rig.drop()
    with pytest.raises(BoardError) as err:
        rig.boards.poll(0)
    assert err.value.url == rig.boards.url and rig.boards.url in str(err.value)
    with pytest.raises(BoardError, match="link is down"):
        rig.boards.poll(0)
    assert rig.boards.down is not None


def test_close_is_idempotent_and_leaves_the_link_down(rig):
    """Close: twice is fine; a back end with a link has it down afterwards."""
    rig.boards.close()
    rig.boards.close()
    assert rig.boards.closed
    if rig.scheme != "sim":
        assert rig.boards.down is not None


@pytest.mark.parametrize("scheme", ["sim", "tcp", "modbus"])
def test_a_station_runs_io_read_first_and_io_write_last_and_times_them(scheme):
    """Station phase order: io:read is the first loop handler, io:write the last (after the
    mailbox); both are timed as handlers of their own in the loop's statistics."""
    from pyrt.scheduler import Loop, WallClock
    from pyrt.station.gripper import build_gripper

    world = GripperWorld(start=-0x100)
    server: BoardServer | ModbusBoardServer | None = None
    url = "sim:"  # the world in this process, the station's own
    if scheme == "tcp":
        server = BoardServer(world, "127.0.0.1", 0, watchdog_s=30.0)
        server.start()
        url = server.url
    elif scheme == "modbus":
        server = ModbusBoardServer(world, load_map(builtin_map("gripper"), GRIPPER_BOARDS),
                                   watchdog_s=30.0)
        server.start()
        url = f"{server.url}?map=builtin:gripper"
    station = build_gripper(Loop(WallClock()), boards=url)
    try:
        names = station.loop._handler_names
        assert names[0] == "io:read" and names[-1] == "io:write", names
        assert names.index("mailbox") < names.index("io:write")
        station.start()
        station.runner.call(lambda: None, name="one tick")
        stats = station.runner.statistics()
        assert stats.tasks["io:read"].calls >= 1 and stats.tasks["io:write"].calls >= 1
    finally:
        station.close()
        if server is not None:
            server.close()
