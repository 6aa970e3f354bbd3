"""Blocks of messages into rosbags' sqlite3 writer with one ``executemany`` each.

rosbags' ``rosbag2.Writer`` with sqlite3 storage runs one ``INSERT`` per message from Python.
:func:`write_rows` inserts a block of rows with ``executemany`` on the same connection and keeps
the counts and time range ``metadata.yaml`` is written from, so the database rows and metadata
are those of the per-message writer (tested). It relies on the internals of the pinned rosbags
version: :func:`supports` says whether they look as expected; if not, write per message.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

__all__ = ['supports', 'write_rows']

_INSERT = 'INSERT INTO messages (topic_id, timestamp, data) VALUES(?, ?, ?)'


def supports(writer: Any) -> bool:
    """Whether ``writer`` (an open ``rosbags.rosbag2.Writer``) has the sqlite3 internals used."""
    storage = getattr(writer, 'storage', None)
    return (
        type(storage).__name__ == 'Sqlite3Writer'
        and hasattr(storage, 'cursor')
        and all(hasattr(writer, name) for name in ('counts', 'min_timestamp', 'max_timestamp'))
        and getattr(writer, 'compression_mode', None) is not None
        and writer.compression_mode.name in ('NONE', 'STORAGE')
    )


def write_rows(writer: Any, rows: Sequence[tuple[int, int, bytes | memoryview]]) -> None:
    """Insert ``(connection id, log time ns, data)`` rows in order, as ``Writer.write`` would."""
    if not rows:
        return
    writer.storage.cursor.executemany(_INSERT, rows)
    counts = writer.counts
    low = high = rows[0][1]
    for cid, stamp, _ in rows:
        counts[cid] += 1
        if stamp < low:
            low = stamp
        elif stamp > high:
            high = stamp
    writer.min_timestamp = min(low, writer.min_timestamp)
    writer.max_timestamp = max(high, writer.max_timestamp)
