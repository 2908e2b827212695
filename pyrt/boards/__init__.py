"""Level 1: register-level boards, their interfaces and their back ends.

8031 RAM image and ports, the gripper cage (:mod:`pyrt.boards.gripper`),
the TIO10's counter and stepper channels, the dataConcentrator's counters
and ADCs; the in-process simulated boards; and the back ends chosen by URL
(:func:`open_boards`: ``sim:``, ``tcp://HOST:PORT``, or a scheme registered
through the ``pyrt.boards`` entry points; see :mod:`pyrt.boards.registry`).
"""

from pyrt.boards.registry import (
    DEFAULT_URL,
    ENTRY_POINT_GROUP,
    Boards,
    BoardURL,
    known_schemes,
    open_boards,
    parse_board_url,
    register_backend,
)

__all__ = [
    "DEFAULT_URL",
    "ENTRY_POINT_GROUP",
    "BoardURL",
    "Boards",
    "known_schemes",
    "open_boards",
    "parse_board_url",
    "register_backend",
]
