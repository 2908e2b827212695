"""The software oscilloscope: channels sampled into a ring buffer, triggers, export
(CSV, npz, MCAP, plots), the live UDP stream, spew."""

from pyrt.scope.export import (
    PLOT_SUFFIXES,
    SAVE_SUFFIXES,
    check_plot_path,
    check_save_path,
    confine,
    plot_frame,
    save_frame,
)
from pyrt.scope.joints import JointStates
from pyrt.scope.scope import MAX_BUFFER_BYTES, MAX_LENGTH, MODES, Frame, Scope, Trigger
from pyrt.scope.sources import Source, compile_sources
from pyrt.scope.spew import Spew
from pyrt.scope.stream import UdpStream

__all__ = [
    "MAX_BUFFER_BYTES",
    "MAX_LENGTH",
    "MODES",
    "PLOT_SUFFIXES",
    "SAVE_SUFFIXES",
    "Frame",
    "JointStates",
    "Scope",
    "Source",
    "Spew",
    "Trigger",
    "UdpStream",
    "check_plot_path",
    "check_save_path",
    "compile_sources",
    "confine",
    "plot_frame",
    "save_frame",
]
