"""The DAQ link: a TCP line-protocol command and status server."""

from pyrt.server.hub import StatusHub
from pyrt.server.protocol import ERROR_CODES, MAX_LINE, format_error, format_reply
from pyrt.server.robot import ObserverRunner, ServedRobot
from pyrt.server.server import Server, is_loopback
from pyrt.server.station import ServedStation

__all__ = [
    "ERROR_CODES",
    "MAX_LINE",
    "ObserverRunner",
    "ServedRobot",
    "ServedStation",
    "Server",
    "StatusHub",
    "format_error",
    "format_reply",
    "is_loopback",
]
