"""The argument parser of every pyrt command: its help is plain text.

Descriptions come from module docstrings and factories' ``description``,
written in reST; :class:`Parser` shows them without reST markup (double
backticks, roles), in this one place.  Sub-parsers made through a
:class:`Parser`'s sub-commands are Parsers too.
"""

from __future__ import annotations

import argparse

from pyrt.component import plain_text

__all__ = ["Parser"]


class Parser(argparse.ArgumentParser):
    """An ``argparse.ArgumentParser`` whose help has no reST markup."""

    def format_help(self) -> str:
        return plain_text(super().format_help())
