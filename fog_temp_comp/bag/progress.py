"""Progress of reading a bag on stderr: messages read and seconds of data (log time)."""

from __future__ import annotations

import sys
import time
from typing import TextIO

from fog_temp_comp.core.units import NS_PER_S

__all__ = ['Progress']


class Progress:
    """Progress on stderr: messages read and seconds of data.

    On a terminal one line redrawn in place (carriage returns); into a file or pipe (a log)
    only the final line, one per bag.
    """

    def __init__(self, label: str, *, quiet: bool = False, stream: TextIO | None = None) -> None:
        self.label = label
        self.quiet = quiet
        self.stream = stream or sys.stderr
        self.messages = 0
        self.first_ns: int | None = None
        self.last_ns = 0
        self._shown = 0.0
        isatty = getattr(self.stream, 'isatty', None)
        self.redraw = bool(isatty and isatty())

    def update(self, messages: int, log_ns: int, first_ns: int | None = None) -> None:
        """Count ``messages`` more, the newest with log time ``log_ns`` (oldest ``first_ns``)."""
        self.messages += messages
        oldest = log_ns if first_ns is None else first_ns
        if self.first_ns is None or oldest < self.first_ns:
            self.first_ns = oldest
        self.last_ns = max(self.last_ns, log_ns)
        now = time.monotonic()
        if self.redraw and not self.quiet and now - self._shown > 0.5:
            self._shown = now
            self._write('\r')

    def close(self) -> None:
        """Print the final line."""
        if not self.quiet:
            self._write('\r' if self.redraw else '')
            self.stream.write('\n')
            self.stream.flush()

    def _write(self, prefix: str) -> None:
        span = (self.last_ns - (self.first_ns or 0)) / NS_PER_S if self.first_ns else 0.0
        self.stream.write(
            f'{prefix}reading {self.label}: {self.messages:,} messages, {span:,.0f} s of data'
        )
        self.stream.flush()
