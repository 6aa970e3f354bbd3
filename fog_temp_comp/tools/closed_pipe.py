"""Standard output that outlives its reader: ``fog-temp-comp calibrate ... | head`` still writes.

When the reader of a pipe goes away (``head`` has its lines, ``less`` is quit), the next write
raises ``BrokenPipeError``. A command that prints its report before it writes its output file
would then stop with the fit done and nothing written. :class:`ClosedPipeSafe` drops what is
printed after the reader left and lets the command finish; the stream's descriptor is pointed
at ``os.devnull`` so that the interpreter's last flush does not fail either (the recipe of
Python's ``signal`` documentation, without the early exit).
"""

from __future__ import annotations

import os
from typing import Any, TextIO

__all__ = ['ClosedPipeSafe']


class ClosedPipeSafe:
    """``stream`` (a text stream); writes after its reader left are dropped, not raised."""

    def __init__(self, stream: TextIO) -> None:
        self.stream = stream
        #: whether the reader went away
        self.closed_by_reader = False

    def write(self, text: str) -> int:
        """Write ``text`` (dropped once the reader left); the characters taken."""
        if not self.closed_by_reader:
            try:
                return self.stream.write(text)
            except BrokenPipeError:
                self._reader_left()
        return len(text)

    def flush(self) -> None:
        """Flush, unless the reader left."""
        if not self.closed_by_reader:
            try:
                self.stream.flush()
            except BrokenPipeError:
                self._reader_left()

    def _reader_left(self) -> None:
        self.closed_by_reader = True
        try:  # the interpreter flushes sys.__stdout__ at exit: let that go nowhere
            devnull = os.open(os.devnull, os.O_WRONLY)
            try:
                os.dup2(devnull, self.stream.fileno())
            finally:
                os.close(devnull)
        except (OSError, ValueError, AttributeError):  # not a file (an in-memory stream)
            pass

    def __getattr__(self, name: str) -> Any:
        return getattr(self.stream, name)
