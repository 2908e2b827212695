"""Self-scheduling tasks built over the robots: database write-back, server poll, scope sampler."""

from pyrt.tasks.writeback import (
    MOVING_PERIOD_NS,
    STATIONARY_PERIOD_NS,
    ZEROLENGTH_PERIOD_NS,
    SyncWriter,
    ThreadWriter,
    Watch,
    WriteBack,
    Writer,
)

__all__ = [
    "MOVING_PERIOD_NS",
    "STATIONARY_PERIOD_NS",
    "ZEROLENGTH_PERIOD_NS",
    "SyncWriter",
    "ThreadWriter",
    "Watch",
    "WriteBack",
    "Writer",
]
