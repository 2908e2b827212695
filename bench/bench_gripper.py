"""Gripper benchmarks: the whole `pyrt gripper --speed max` stack, idle and during P moves.

Run: ``python -m pytest bench/bench_gripper.py --benchmark-only -s``.
Each benchmark reports, in ``extra_info`` and on stdout, the simulated
seconds per wall second (target: at least 200x real time at the 1 ms tick)
and the wall-clock µs per tick.  The stack is the one the CLI builds: the
jaw plant, the controller (ready queue in RAM + stall watchdog), a stopped
scope and the runner's mailbox, on a SimClock.
"""

from __future__ import annotations

import pytest

from pyrt.boards.gripper import GRIPPER_CAGE, GripperBoard
from pyrt.boards.i8031 import I8031
from pyrt.boards.registers import RegisterBoard
from pyrt.robots.gripper import GripperController
from pyrt.scheduler import Loop, SimClock
from pyrt.scheduler.runner import Runner
from pyrt.scope import Scope
from pyrt.sim.gripper import JawPlant

TARGET_RATIO = 200.0


def make_stack(tick_us: int = 1000):
    cpu = I8031()
    regs = RegisterBoard(GRIPPER_CAGE)  # the cage's register file, the jaws behind it
    board = GripperBoard(regs, cpu)
    plant = JawPlant(regs)
    loop = Loop(SimClock(), period_ns=tick_us * 1000, timing=True)
    ctl = GripperController(cpu)
    loop.attach(plant.step, name="jaws")
    loop.attach(board.poll, name="encoder")
    ctl.attach(loop)
    loop.attach(Scope().sample, name="scope")  # as the CLI: a scope, stopped
    ctl.power_up()
    runner = Runner(loop)
    runner.start()
    job = runner.call(ctl.start_init)
    assert runner.wait_until(lambda: job.done, 60.0) and job.value().ok
    return runner, ctl, loop


def report(benchmark, sim_s: float, ticks: int, label: str) -> None:
    """Ratios from the best round (the machine is shared: the best is the code's
    own cost) and from the mean."""
    best, mean = benchmark.stats.stats.min, benchmark.stats.stats.mean
    ratio, ratio_mean = sim_s / best, sim_s / mean
    us_tick = best / ticks * 1e6
    benchmark.extra_info.update(
        sim_s_per_wall_s=round(ratio, 1),
        sim_s_per_wall_s_mean=round(ratio_mean, 1),
        us_per_tick=round(us_tick, 3),
        target_ratio=TARGET_RATIO,
    )
    print(
        f"\n{label}: {ratio:.0f}x real time best, {ratio_mean:.0f}x mean "
        f"({us_tick:.2f} µs per tick; target {TARGET_RATIO:g}x)"
    )


@pytest.mark.benchmark(group="gripper")
@pytest.mark.parametrize("tick_us", [1000, 250])
def test_gripper_idle(benchmark, tick_us):
    """Idle gripper (three routines, plant at rest): 5 s of simulated time per round."""
    runner, _ctl, _loop = make_stack(tick_us)
    seconds = 5.0
    benchmark.pedantic(runner.sleep, args=(seconds,), rounds=7, iterations=1)
    report(benchmark, seconds, int(seconds * 1e6 / tick_us), f"idle, tick {tick_us} µs")
    runner.stop()


@pytest.mark.benchmark(group="gripper")
def test_gripper_p_move(benchmark):
    """A P move closed (D600) and back open: simulated time of both moves per round."""
    runner, ctl, loop = make_stack()
    sim = {"ns": 0, "ticks": 0}

    def moves() -> None:
        t0, k0 = loop.now_ns, loop.tick_index
        for target in (-0x2A00, 0):
            runner.call(ctl.move, target)
            assert runner.wait_until(lambda: not ctl.moving, 60.0)
        sim["ns"] += loop.now_ns - t0
        sim["ticks"] += loop.tick_index - k0

    rounds = 5
    benchmark.pedantic(moves, rounds=rounds, iterations=1)
    report(benchmark, sim["ns"] / rounds / 1e9, sim["ticks"] // rounds, "P D600 and back")
    runner.stop()


@pytest.mark.benchmark(group="gripper")
def test_gripper_p_move_bare_loop(benchmark):
    """The same moves on the bare loop (plant + controller, no runner, no scope):
    the controller's and the simulation's own cost."""
    cpu = I8031()
    regs = RegisterBoard(GRIPPER_CAGE)  # the cage's register file, the jaws behind it
    board = GripperBoard(regs, cpu)
    plant = JawPlant(regs)
    loop = Loop(SimClock(), timing=True)
    ctl = GripperController(cpu)
    loop.attach(plant.step, name="jaws")
    loop.attach(board.poll, name="encoder")
    ctl.attach(loop)
    ctl.power_up()
    job = ctl.start_init()
    assert loop.run_until(lambda: job.done, 60_000) and job.value().ok
    sim = {"ns": 0, "ticks": 0}

    def moves() -> None:
        t0, k0 = loop.now_ns, loop.tick_index
        for target in (-0x2A00, 0):
            ctl.move(target)
            assert loop.run_until(lambda: not ctl.moving, 60_000)
        sim["ns"] += loop.now_ns - t0
        sim["ticks"] += loop.tick_index - k0

    rounds = 5
    benchmark.pedantic(moves, rounds=rounds, iterations=1)
    report(benchmark, sim["ns"] / rounds / 1e9, sim["ticks"] // rounds, "P D600 and back, bare loop")


#: The supervision's budget per MVJAWS run, µs.
SUPERVISION_TARGET_US = 0.2


@pytest.mark.benchmark(group="gripper-supervision")
def test_supervision_cost_per_jaw_move_call(benchmark):
    """MVJAWS mid-move with the move's supervision armed, and the same run disarmed:
    the difference is what the supervision costs per jaw-move call (target < 0.2 µs)."""
    import time

    from pyrt.boards.i8031 import ERROR_CNT
    from pyrt.tasks.jawmove import mvjaws

    _runner, ctl, _loop = make_stack()
    ctl.move(-0x1000)  # drive bit on, supervisor armed with a deadline seconds away
    sup = ctl.supervisor
    n = 2_000

    def calls(active: bool) -> float:
        ctl.ram[ERROR_CNT], ctl.ram[ERROR_CNT + 1] = 0x80, 0x10  # +4096: far from the target
        sup.active = active
        sup.side = 1  # mid-move: no sign change, the common path
        t0 = time.perf_counter()
        for _ in range(n):
            mvjaws(ctl)
        return (time.perf_counter() - t0) / n * 1e6

    armed = bare = float("inf")
    for _ in range(100):  # interleaved, so that the machine's load falls on both alike
        armed = min(armed, calls(True))
        bare = min(bare, calls(False))
    sup.active = True
    benchmark.pedantic(mvjaws, args=(ctl,), rounds=2000, iterations=10)
    cost = armed - bare
    benchmark.extra_info.update(mvjaws_us=round(bare, 3), mvjaws_supervised_us=round(armed, 3),
                                supervision_us=round(cost, 3), target_us=SUPERVISION_TARGET_US)
    print(f"\nMVJAWS {bare:.3f} µs per call bare, {armed:.3f} µs supervised: supervision "
          f"{cost:.3f} µs per jaw-move call (target < {SUPERVISION_TARGET_US} µs)")
    _runner.stop()
