"""A station of a few lines built only from ``pyrt``'s public names, for the launcher's tests."""

from __future__ import annotations

from pyrt import Arg, Component, Signal, Station, StationFactory, command


class Counter(Component):
    """Counts ticks by a step the operator sets."""

    name = "counter"

    def __init__(self) -> None:
        self.count = 0
        self.step = 1

    def signals(self) -> list[Signal]:
        return [Signal.attr("count", "ticks", self, "count", "ticks counted")]

    @command(Arg("N", int, lo=1, hi=100, units="ticks"), name="step")
    def set_step(self, n: int) -> str:
        """counter step N: count N a tick."""
        self.step = n
        return f"step {n}"

    def tick(self, now_ns: int) -> None:
        self.count += self.step


def build(loop, args=None):
    """A counter station: one component counting ticks."""
    station = Station(loop)
    station.name = "counter"
    counter = Counter()
    loop.attach(counter.tick, name="counter")
    station.adopt(counter)
    return station


class CounterFactory(StationFactory):
    """A counter station with an option of its own."""

    name = "counter"
    summary = "count ticks"
    default_speed = "max"

    def add_arguments(self, parser):
        parser.add_argument("--first-step", type=int, default=1, help="the step at start")

    def build(self, loop, args):
        station = build(loop)
        station.root.step = args.first_step
        return station
