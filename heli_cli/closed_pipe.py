"""A standard output that a reader may close early: ``heli identify ... | head -6``.

The commands print their results *between* the files they write (``heli identify`` prints the model, then draws
the figures and writes ``report.html``, which embeds them). When the reader of a pipe stops reading, the next
``print`` raises :class:`BrokenPipeError` (Python ignores ``SIGPIPE``), and the command used to end there with a
complete model and an incomplete folder, reported as a bug. What was printed was only a view of what is written:
the reader has seen what it wanted, so the command goes on silently and writes everything it promised.

:func:`guarded_stdout` wraps ``sys.stdout`` for the run. The first write or flush that meets a closed pipe
points the standard output's file descriptor at ``os.devnull`` (so that nothing buffered, nor the interpreter's
last flush at exit, meets the pipe again: Python's documented way, "Note on SIGPIPE" in the :mod:`signal`
documentation) and every later write is dropped.
"""

from __future__ import annotations

import contextlib
import os
import sys


class ClosedPipeGuard:
    """A text stream writing to ``stream`` until its reader has gone, then nowhere.

    Attributes
    ----------
    reader_gone : bool
        A write or flush met a closed pipe; nothing is written after it.
    """

    def __init__(self, stream):
        self._stream = stream
        self.reader_gone = False

    def write(self, text: str) -> int:
        if not self.reader_gone:
            try:
                return self._stream.write(text)
            except BrokenPipeError:
                self._silence()
        return len(text)

    def flush(self) -> None:
        if not self.reader_gone:
            try:
                self._stream.flush()
            except BrokenPipeError:
                self._silence()

    def _silence(self) -> None:
        self.reader_gone = True
        try:
            fd = self._stream.fileno()
        except (AttributeError, OSError, ValueError):  # not a file (a test's StringIO): nothing to redirect
            return
        devnull = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(devnull, fd)  # the stream's buffered bytes now go nowhere, at its next flush and at exit
        finally:
            os.close(devnull)

    def __getattr__(self, name):  # isatty, fileno, encoding, ...: the wrapped stream's
        return getattr(self._stream, name)


@contextlib.contextmanager
def guarded_stdout():
    """``sys.stdout`` wrapped in a :class:`ClosedPipeGuard` for the block, then restored."""
    original = sys.stdout
    guard = ClosedPipeGuard(original)
    sys.stdout = guard
    try:
        yield guard
    finally:
        guard.flush()  # a pipe's block buffer may hold every line yet: its closed reader is met here, not at exit
        if sys.stdout is guard:
            sys.stdout = original
