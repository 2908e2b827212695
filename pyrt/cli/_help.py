"""The argument parser of every pyrt command: its help is plain text.

Descriptions come from module docstrings and factories' ``description``,
written in reST; :class:`Parser` shows them without reST markup (double
backticks, roles), in this one place.  Sub-parsers made through a
:class:`Parser`'s sub-commands are Parsers too.  A word that is no choice
(``pyrt manipulatr``) is answered with the nearest ones ("did you mean
'manipulator'?").
"""

from __future__ import annotations

import argparse
import difflib
import re
from typing import NoReturn

from pyrt.component import plain_text

__all__ = ["Parser"]


class Parser(argparse.ArgumentParser):
    """An ``argparse.ArgumentParser`` whose help has no reST markup."""

    def format_help(self) -> str:
        return plain_text(super().format_help())

    def error(self, message: str) -> NoReturn:
        """The usage and ``message`` on stderr, exit status 2; for an invalid
        choice, the nearest choices too."""
        m = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)$", message)
        if m:
            choices = (re.findall(r"'([^']*)'", m.group(2))  # quoted up to Python 3.12
                       or [c.strip() for c in m.group(2).split(",")])
            near = difflib.get_close_matches(m.group(1), choices, n=3, cutoff=0.6)
            if near:
                message += "; did you mean " + " or ".join(f"'{n}'" for n in near) + "?"
        super().error(message)
