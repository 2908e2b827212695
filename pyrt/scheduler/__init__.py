"""Clocks, the ready queue, the tick loop and its timing: no robot knowledge."""

from pyrt.scheduler.clock import Clock, SimClock, WallClock
from pyrt.scheduler.loop import Job, Loop
from pyrt.scheduler.rategroup import RateGroup
from pyrt.scheduler.readyqueue import ByteImage, ByteRef, ReadyQueue, Routine
from pyrt.scheduler.stats import Distribution, GroupStatistics, LoopStatistics, TaskStatistics
from pyrt.scheduler.task import Task, install
from pyrt.scheduler.timinglog import TimingLog, TimingReport, read_timing_log

__all__ = [
    "ByteImage",
    "ByteRef",
    "Clock",
    "Distribution",
    "GroupStatistics",
    "Job",
    "Loop",
    "LoopStatistics",
    "RateGroup",
    "ReadyQueue",
    "Routine",
    "SimClock",
    "Task",
    "TaskStatistics",
    "TimingLog",
    "TimingReport",
    "WallClock",
    "install",
    "read_timing_log",
]
