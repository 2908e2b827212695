"""A line console for any pyrt command interpreter (the gripper's, the manipulator's).

On a terminal: history and arrow-key line editing with prompt_toolkit, and
messages from the control loop (faults, readloop lines) printed above the
line being typed, never through it (``patch_stdout``).  Without
prompt_toolkit, ``input()`` with readline when it is there; loop messages
are then printed before each prompt.

When stdin is not a terminal, plain lines: the same commands run as a
script, each prompt is printed with the line echoed after it (as the 8031
echoed every character it read), and the console ends at end of input.
A script fails loudly (docs/scripts.md): a line that failed (the
interpreter counts its failures in ``failures``: a refused command, a
fault) is named on stderr with its file, number and text, the script stops
there unless ``keep_going``, and :meth:`Console.run` returns 1.

The interpreter is any object with ``prompt`` and ``onecmd(line) -> bool``
(True ends the session) writing to its ``stdout`` attribute; ``messages``
drains the loop's asynchronous lines (``Runner.messages``).  When it also
has ``completions()`` (the nested table of words, objects and their verbs
that :class:`~pyrt.commands.RobotShell` derives from the command records),
Tab completes from it, case-insensitively, on both line editors.
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading
from collections.abc import Callable
from typing import Any, Protocol, TextIO

from pyrt.errors import ConfigError

__all__ = ["Console", "Interpreter", "ReaderGone", "complete", "silence"]

#: How often the terminal console looks for loop messages, seconds.
POLL_S = 0.1
#: The longest command line read from a script (characters); a longer one is
#: refused whole, without being kept in memory.
MAX_LINE = 4096
#: How much of a line a script's echo shows (the rest is counted, not copied).
ECHO_MAX = 200


def _echo(line: str) -> str:
    """A read line as the transcript shows it: at most ECHO_MAX characters."""
    body = line.rstrip("\r\n")
    if len(body) > ECHO_MAX:
        body = f"{body[:ECHO_MAX]}... ({len(body)} characters)"
    return body + "\n"


class ReaderGone(BaseException):
    """Whoever read the console's output has gone (a closed pipe: ``| head``).

    A BaseException, so that a command's own error handling (which turns
    every Exception into one line of output) lets it through to the console."""


def silence(stream: TextIO) -> None:
    """Point ``stream``'s file descriptor at the null device: what is still
    buffered for a reader that has gone, and whatever is written later
    (closing lines, the interpreter's last flush), goes nowhere, quietly."""
    with contextlib.suppress(OSError, ValueError, AttributeError):
        fd = stream.fileno()
        null = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(null, fd)
        finally:
            os.close(null)


class _Output:
    """A console's output stream: a reader that has gone (EPIPE) is
    :class:`ReaderGone`, not an error of the command that was writing."""

    #: How much of a script line's output is kept to say why it failed (characters).
    KEEP = 4000

    def __init__(self, out: TextIO):
        self._out = out
        #: What was written since :meth:`mark` (at most KEEP characters), or None.
        self.kept: list[str] | None = None
        self._kept_n = 0

    def mark(self) -> None:
        """Keep what is written from here on (a script line's output)."""
        self.kept, self._kept_n = [], 0

    def write(self, text: str) -> int:
        if self.kept is not None and self._kept_n < self.KEEP:
            self.kept.append(text)
            self._kept_n += len(text)
        try:
            return self._out.write(text)
        except BrokenPipeError:
            raise ReaderGone from None

    def flush(self) -> None:
        try:
            self._out.flush()
        except BrokenPipeError:
            raise ReaderGone from None

    def __getattr__(self, name: str) -> Any:
        return getattr(self._out, name)


def _guarded(out: TextIO) -> TextIO:
    return out if isinstance(out, _Output) else _Output(out)  # type: ignore[return-value]


class Interpreter(Protocol):
    """What a console drives."""

    stdout: TextIO

    @property
    def prompt(self) -> str: ...

    def onecmd(self, line: str) -> bool: ...


def complete(table: dict[str, Any] | None, line: str) -> list[str]:
    """The words that may follow ``line`` (the text before the cursor) in the
    nested completion ``table``: a dict of word -> its own table or None."""
    words = line.split()
    partial = "" if not words or line[-1:].isspace() else words.pop()
    node = table
    for w in words:
        if not isinstance(node, dict):
            return []
        key = next((k for k in node if k.lower() == w.lower()), None)
        if key is None:
            return []
        node = node[key]
    if not isinstance(node, dict):
        return []
    p = partial.lower()
    return sorted(k for k in node if k.lower().startswith(p))


class Console:
    """Read lines, run them through ``shell``, print the loop's messages."""

    def __init__(
        self,
        shell: Interpreter,
        stdin: TextIO | None = None,
        stdout: TextIO | None = None,
        messages: Callable[[], list[str]] | None = None,
        history_file: str | None = None,
        status: Callable[[], str] | None = None,
        status_period_s: float = 0.25,
        keep_going: bool = True,
        errors: TextIO | None = None,
        what: str = "",
    ):
        self.shell = shell
        self.stdin = stdin if stdin is not None else sys.stdin
        # A byte that is not UTF-8 (line noise, a binary file piped in) is a
        # bad command like any other, not the end of the console: decode it
        # as U+FFFD and let the command parser refuse it.
        reconfigure = getattr(self.stdin, "reconfigure", None)
        if callable(reconfigure):
            with contextlib.suppress(ValueError, OSError, AttributeError):
                reconfigure(errors="replace")
        out = stdout if stdout is not None else sys.stdout
        if out is None:  # no standard output at all (a windowed interpreter)
            raise ConfigError("the console needs an output stream: sys.stdout is None")
        # The interpreter writes where the console does: both through one
        # guard, so that a reader that goes away ends the console quietly.
        shares = getattr(shell, "stdout", None) is out
        self.stdout = _guarded(out)
        if shares:
            shell.stdout = self.stdout
        self.messages = messages if messages is not None else (lambda: [])
        self.history_file = history_file
        #: The live status line (a terminal only: prompt_toolkit's bottom
        #: toolbar, refreshed every ``status_period_s``); never written to a pipe.
        self.status = status
        self.status_period_s = status_period_s
        #: How the last :meth:`run` ended: "quit", "end of input" or "output closed".
        self.ended_by = "quit"
        #: True when the run ended because the reader of its output went away.
        self.reader_gone = False
        #: A script (stdin not a terminal) runs on after a line that failed
        #: (and still returns 1); False stops it at the first (halcmd's way).
        self.keep_going = keep_going
        #: Where a script's failed lines are named (None: ``sys.stderr`` at the time).
        self.errors = errors
        #: The program's name on those lines (``pyrt gripper``), or ''.
        self.what = what
        #: The script's lines that failed: (number, text, why).
        self.failed: list[tuple[int, str, str]] = []

    def interactive(self) -> bool:
        """True when both ends are a terminal (line editing and history)."""
        try:
            return bool(self.stdin.isatty() and self.stdout.isatty())
        except (AttributeError, ValueError):
            return False

    def run(self) -> int:
        """Run until ``quit`` or end of input; return the exit status (0; 1
        when a script's line failed, see the module text).

        When the reader of the output goes away (``| head``), the console
        ends there, quietly (:attr:`reader_gone`; its output silenced), and
        returns 0: the caller closes the robot as at end of input."""
        try:
            if self.interactive():
                try:
                    import prompt_toolkit  # noqa: F401
                except ImportError:
                    return self._run_input()
                return self._run_prompt_toolkit()
            return self._run_lines()
        except ReaderGone:
            self.ended_by = "output closed"
            self.reader_gone = True
            silence(self.stdout)
            return 0

    # -- output of the loop ------------------------------------------------------

    def flush_messages(self, out: TextIO | None = None) -> None:
        """Print the loop's pending messages, one per line."""
        out = out if out is not None else self.stdout
        lines = self.messages()
        if lines:
            out.write("".join(line + "\n" for line in lines))
            out.flush()

    # -- a pipe or a file: a script ----------------------------------------------

    def _failures(self) -> int:
        n = getattr(self.shell, "failures", 0)
        return n if isinstance(n, int) else 0

    def _line_failed(self, number: int, text: str, why: str, last: bool = False) -> bool:
        """Name a script's failed line on the error stream; True when the script
        stops (``last``: there is nothing after it to stop)."""
        redact = getattr(self.shell, "redact", None)
        if callable(redact):
            text = redact(text)
        self.failed.append((number, text, why))
        where = f"{self.source_name()}:{number}"
        stop = not self.keep_going and not last
        tail = "; the script stops here (-k runs on)" if stop else ""
        self._tell(f"{where}: {text[:ECHO_MAX]!r} failed: {why}{tail}")
        if stop:
            low = why.lower()
            kind = "an error" if low.startswith(("error", "internal")) else (
                "a fault" if "fault" in low else "it failed")
            self.ended_by = f"stopped at line {number} ({kind})"
        return stop

    def _tell(self, line: str) -> None:
        err = self.errors if self.errors is not None else sys.stderr
        head = f"{self.what}: " if self.what else ""
        with contextlib.suppress(OSError, ValueError, AttributeError):
            if err is not None:
                err.write(head + line + "\n")
                err.flush()

    def source_name(self) -> str:
        """The script's name for its failed lines: its file when stdin is one, else stdin."""
        name = getattr(self.stdin, "name", None)
        if isinstance(name, str) and name and not name.startswith("<"):
            return name
        with contextlib.suppress(OSError, ValueError, AttributeError, TypeError):
            path = os.readlink(f"/proc/self/fd/{self.stdin.fileno()}")
            if os.path.isfile(path):
                rel = os.path.relpath(path)
                return rel if not rel.startswith("..") else path
        return "stdin"

    def _why(self, out: _Output, fallback: str) -> str:
        """What a failed line said about it (its first error or FAULT line)."""
        said = "".join(out.kept or []).splitlines()
        out.kept = None
        for text in said:
            t = text.strip()
            if t.startswith(("error:", "internal error:")) or "fault" in t[:40].lower():
                return t[:ECHO_MAX]
        return fallback

    def _mark(self, guard: _Output | None) -> int:
        """Start keeping a line's output; the failures counted so far."""
        if guard is not None:
            guard.mark()
        return self._failures()

    def _failed_since(self, before: int, guard: _Output | None, number: int, text: str,
                      fallback: str, *, at_end: bool = False) -> bool:
        """If line ``number`` failed since ``before`` (its own failure, or a fault
        that came after it), name it; True when the script stops there."""
        if self._failures() <= before:
            return False
        why = self._why(guard, fallback) if guard is not None else fallback
        if not number:  # before the first line: a start-up command or a fault then
            text = "(start-up, before the first line)"
        return self._line_failed(number, text, why, last=at_end)

    def _run_lines(self) -> int:
        out = self.stdout
        mine = getattr(self.shell, "stdout", None)  # where the line's output goes
        guard = mine if isinstance(mine, _Output) else (
            out if isinstance(out, _Output) else None)
        number, last, stopped = 0, "", False
        first = True
        while True:
            before = self._mark(guard)
            if first:  # what start-up said before the first line counts too
                before, first = 0, False
            self.flush_messages()  # a fault since the last line is that line's
            if self._failed_since(before, guard, number, last, "a fault"):
                stopped = True
                break
            out.write(self.shell.prompt)
            out.flush()
            line = self.stdin.readline(MAX_LINE + 1)
            if not line:
                out.write("\n")
                self.ended_by = "end of input"
                break
            number += 1
            if len(line) > MAX_LINE and not line.endswith("\n"):
                n = len(line)
                while True:  # the rest of the line, read and dropped
                    more = self.stdin.readline(65536)
                    n += len(more.rstrip("\r\n"))
                    if not more or more.endswith("\n"):
                        break
                out.write(f"{line[:ECHO_MAX]}... ({n} characters)\n")
                why = (f"error: a line of {n} characters is refused (at most {MAX_LINE}); "
                       "nothing done")
                out.write(why + "\n")
                last = f"{line[:40]}..."
                if self._line_failed(number, last, why):
                    stopped = True
                    break
                continue
            out.write(_echo(line))
            last = line.rstrip("\r\n")
            before = self._mark(guard)
            ended = self.shell.onecmd(last)
            if self._failed_since(before, guard, number, last, "failed"):
                stopped = True
                break
            if ended:
                break
        before = self._mark(guard)
        self.flush_messages()  # what came after the last line: a fault is its failure
        if not stopped:
            self._failed_since(before, guard, number, last, "a fault", at_end=True)
        if guard is not None:
            guard.kept = None
        out.flush()
        if self.failed and self.keep_going and len(self.failed) > 1:
            lines = ", ".join(str(n) for n, _t, _w in self.failed)
            self._tell(f"{self.source_name()}: {len(self.failed)} lines failed: {lines}")
        return 1 if self.failed else 0

    # -- a terminal ----------------------------------------------------------------

    def _run_prompt_toolkit(self) -> int:
        from prompt_toolkit import PromptSession
        from prompt_toolkit.history import FileHistory, InMemoryHistory
        from prompt_toolkit.patch_stdout import patch_stdout

        history = FileHistory(self.history_file) if self.history_file else InMemoryHistory()
        session: PromptSession[str] = PromptSession(
            history=history, completer=self._completer(),
            bottom_toolbar=self._status_line if self.status is not None else None,
            refresh_interval=self.status_period_s if self.status is not None else 0)
        stop = threading.Event()
        saved = self.shell.stdout
        with patch_stdout(raw=True):
            proxy = sys.stdout
            self.shell.stdout = proxy

            def pump() -> None:
                while not stop.wait(POLL_S):
                    self.flush_messages(proxy)

            thread = threading.Thread(target=pump, name="console-messages", daemon=True)
            thread.start()
            try:
                while True:
                    try:
                        line = session.prompt(self.shell.prompt)
                    except KeyboardInterrupt:
                        self._interrupted(proxy, at_prompt=True)
                        continue
                    except EOFError:
                        self.ended_by = "end of input"
                        break
                    if self._onecmd_interruptible(line, proxy):
                        break
            finally:
                stop.set()
                thread.join(1.0)
                self.flush_messages(proxy)
                self.shell.stdout = saved
        return 0

    def _status_line(self) -> str:
        """The status line's text; a status that cannot be read says why, in one line."""
        assert self.status is not None
        try:
            return " " + self.status().replace("\n", "  ")
        except Exception as exc:  # the toolbar must never take the console down
            return f" status unavailable: {type(exc).__name__}: {exc}"[:200]

    def _table(self) -> dict[str, Any] | None:
        table = getattr(self.shell, "completions", None)
        return table() if callable(table) else None

    def _completer(self) -> Any:
        """A prompt_toolkit completer over :func:`complete` (None without a table)."""
        if self._table() is None:
            return None
        from prompt_toolkit.completion import Completer, Completion

        console = self

        class _Words(Completer):
            def get_completions(self, document: Any, complete_event: Any) -> Any:
                text = document.text_before_cursor
                partial = "" if not text or text[-1].isspace() else text.split()[-1]
                for word in complete(console._table(), text):
                    yield Completion(word, start_position=-len(partial))

        return _Words()

    def _run_input(self) -> int:
        with contextlib.suppress(ImportError):  # line editing and history for input()
            import readline

            if self._table() is not None:
                def word(text: str, state: int) -> str | None:
                    line = readline.get_line_buffer()[: readline.get_endidx()]
                    found = complete(self._table(), line)
                    return found[state] + " " if state < len(found) else None

                readline.set_completer(word)
                readline.set_completer_delims(" \t")
                readline.parse_and_bind("tab: complete")
        while True:
            self.flush_messages()
            try:
                line = input(self.shell.prompt)
            except KeyboardInterrupt:
                self.stdout.write("\n")
                self._interrupted(self.stdout, at_prompt=True)
                continue
            except EOFError:
                self.stdout.write("\n")
                self.ended_by = "end of input"
                break
            if self._onecmd_interruptible(line, self.stdout):
                break
        self.flush_messages()
        return 0

    def _onecmd_interruptible(self, line: str, out: TextIO) -> bool:
        """Run a line; Ctrl-C abandons the command (a wait, say) and keeps the session."""
        try:
            return self.shell.onecmd(line)
        except KeyboardInterrupt:
            self._interrupted(out, at_prompt=False)
            return False

    def _interrupted(self, out: TextIO, *, at_prompt: bool) -> None:
        """Ctrl-C: the interpreter's ``interrupt(at_prompt)`` says what it did
        (a robot shell stops a running move; idle at the prompt it only gives
        a hint); without one, "interrupted" (a command was abandoned)."""
        interrupt = getattr(self.shell, "interrupt", None)
        if callable(interrupt):
            try:
                said = interrupt(at_prompt)
            except KeyboardInterrupt:  # a second Ctrl-C while stopping: try once more
                said = interrupt(at_prompt)
        else:
            said = None if at_prompt else "interrupted"
        if said:
            out.write(said + "\n")
            out.flush()
