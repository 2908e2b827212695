"""stdout for the ``pyrt`` program: a reader that has gone ends any command quietly.

A closed pipe (``pyrt top 5050 --count 3 | head -1``) makes a write or a
flush raise ``BrokenPipeError``, an ``OSError``; a command that reports its
own I/O errors (a server that went away, a file that cannot be read) would
catch it and say ``[Errno 32] Broken pipe``, exit 1.  :class:`PipeGuard`
turns it into :class:`~pyrt.console.ReaderGone`, which no command's error
handling takes, so that :func:`pyrt.cli.entry` ends the program quietly, as
a reader leaving is no failure of the program.
"""

from __future__ import annotations

from typing import Any, TextIO

from pyrt.console import ReaderGone

__all__ = ["PipeGuard"]


class PipeGuard:
    """``stream`` with write and flush raising ReaderGone when the reader has gone;
    everything else is the stream's."""

    def __init__(self, stream: TextIO):
        self._stream = stream

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            raise ReaderGone from None

    def writelines(self, lines: Any) -> None:
        for line in lines:
            self.write(line)

    def flush(self) -> None:
        try:
            self._stream.flush()
        except BrokenPipeError:
            raise ReaderGone from None

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)
