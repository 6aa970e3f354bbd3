"""Read a bag by header stamp, or by receive time where its two streams' clocks are hours apart.

Aligned by header stamp (the default), a gyro stamped by the computer and a temperature stamped
by its sensor's clock since power-on are decades apart. The bag's receive times are one clock
for both: the reader stops at the first chunks that show it
(:class:`~fog_temp_comp.bag.unstamped.ClocksApartError`) and the bag is read again by receive time,
with a ``NOTE:`` line. Clocks seconds or minutes apart (GPS time against UTC, 18 s) stay on the
header stamps, with :mod:`fog_temp_comp.bag.unstamped`'s warning.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any, TextIO, TypeVar

from fog_temp_comp.bag.unstamped import ClocksApartError

__all__ = ['on_one_clock']

T = TypeVar('T')


def on_one_clock(
    read: Callable[..., T],
    path: str | Path,
    *args: Any,
    time_source: str = 'header',
    stderr: TextIO | None = None,
    **kwargs: Any,
) -> T:
    """``read(path, *args, time_source=..., **kwargs)``, again by receive time if need be."""
    try:
        return read(path, *args, time_source=time_source, **kwargs)
    except ClocksApartError as apart:
        print(apart.note(path), file=stderr or sys.stderr)
        return read(path, *args, time_source='receive', **kwargs)
