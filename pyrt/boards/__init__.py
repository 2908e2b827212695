"""Level 1: register-level boards, their interfaces and their back ends.

Board kinds that declare their registers (:class:`BoardKind`,
:class:`Register`; :mod:`pyrt.boards.registers`) and the generic
in-process :class:`RegisterBoard`; the built-in kinds and their typed
views over any register access (:mod:`pyrt.boards.kinds`): the 8031 RAM
image and ports with the gripper cage (:mod:`pyrt.boards.gripper`), the
TIO10's counter and stepper channels, the dataConcentrator's counters and
ADCs; and the back ends chosen by URL (:func:`open_boards`: ``sim:``,
``tcp://HOST:PORT``, or a scheme registered through the ``pyrt.boards``
entry points; see :mod:`pyrt.boards.registry`), which open the boards a
station declares as a :class:`Boards` mapping.
"""

from pyrt.boards.backend import Backend
from pyrt.boards.registers import INPUT, OUTPUT, BoardKind, Register, RegisterBoard
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
    "INPUT",
    "OUTPUT",
    "Backend",
    "BoardKind",
    "BoardURL",
    "Boards",
    "Register",
    "RegisterBoard",
    "known_schemes",
    "open_boards",
    "parse_board_url",
    "register_backend",
]
