"""Fast raw reading of rosbag2 sqlite3 bags (Humble's default storage).

``AnyReader.messages()`` joins every row with the topics table and yields a tuple per message
through several generators. :func:`scan_sqlite` asks the database for one topic at a time,
in rosbags' order (by log time, through the bag's timestamp index), and returns the raw CDR
payloads in batches for the vectorised decoders of :mod:`fog_temp_comp.bag.cdr`. It uses
``apsw``, the SQLite binding rosbags itself reads with (it fetches rows about 1.5x faster than
the standard library's ``sqlite3``), opens the file read-only and immutable, and pauses the
cyclic garbage collector while a batch's row tuples exist (they are freed by reference
counting before it resumes).

Bags whose messages are compressed (``compression_mode`` in ``metadata.yaml``) are not
handled here: :func:`plain_sqlite_files` returns None for them and the caller falls back to
rosbags.
"""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager
from itertools import islice
from pathlib import Path
from typing import Any

import apsw
import numpy as np
import yaml
from numpy.typing import NDArray

__all__ = [
    'loose_data_files',
    'loose_sqlite_files',
    'metadata_counts',
    'nth_log_time',
    'plain_sqlite_files',
    'scan_sqlite',
    'topic_types',
]

Batch = tuple[str, NDArray[np.int64] | None, list[bytes]]


def plain_sqlite_files(path: str | Path) -> list[Path] | None:
    """The ``.db3`` files of an uncompressed rosbag2 sqlite3 bag, in order; else None.

    ``path`` is a bag directory (files from ``metadata.yaml``) or a single ``.db3`` file.
    """
    path = Path(path)
    if path.suffix == '.db3' and path.is_file():
        return [path]
    metadata = path / 'metadata.yaml'
    if not path.is_dir() or not metadata.is_file():
        return None
    try:
        info = yaml.safe_load(metadata.read_text())['rosbag2_bagfile_information']
        compression = str(info.get('compression_mode', '') or '').lower()
        if info.get('storage_identifier') != 'sqlite3' or compression not in ('', 'none'):
            return None
        files = [path / name for name in info['relative_file_paths']]
    except (yaml.YAMLError, KeyError, TypeError, AttributeError):
        return None
    if not files or not all(f.suffix == '.db3' and f.is_file() for f in files):
        return None
    return files


def loose_sqlite_files(path: str | Path) -> tuple[list[Path], str] | None:
    """The ``.db3`` files of a bag directory whose ``metadata.yaml`` is missing or stale.

    Returns (files in name order, what is wrong with the metadata), or None when the
    directory has no ``.db3`` files or its metadata lists exactly the files present.
    """
    return loose_data_files(path, '.db3')


def loose_data_files(path: str | Path, suffix: str) -> tuple[list[Path], str] | None:
    """The ``suffix`` files of a bag directory whose ``metadata.yaml`` is missing or stale.

    Returns (files in name order, what is wrong with the metadata), or None when the
    directory has no such files or its metadata lists exactly the files present. Files it
    does not list are named (one added to the directory, e.g. an output written there, is
    read too: the files present are the bag's data, as after a recorder killed).
    """
    path = Path(path)
    if not path.is_dir():
        return None
    files = sorted(path.glob('*' + suffix))
    if not files:
        return None
    metadata = path / 'metadata.yaml'
    if not metadata.is_file():
        return files, f'no metadata.yaml (recorder killed?): read the {suffix} files'
    try:
        info = yaml.safe_load(metadata.read_text())['rosbag2_bagfile_information']
        listed = sorted(path / name for name in info['relative_file_paths'])
    except (yaml.YAMLError, KeyError, TypeError, AttributeError, UnicodeDecodeError):
        return files, f'unreadable metadata.yaml: read the {suffix} files'
    if listed == files:
        return None
    unlisted = [f.name for f in files if f not in listed]
    if unlisted and all(f in files for f in listed):
        return files, (
            f'stale metadata.yaml (does not list {", ".join(unlisted)}: added to the bag '
            f'directory?): read the {suffix} files present'
        )
    return files, f'stale metadata.yaml (lists other files): read the {suffix} files present'


def metadata_counts(path: str | Path) -> dict[str, int]:
    """``{topic: message count}`` that a bag directory's ``metadata.yaml`` states ({} if none)."""
    metadata = Path(path) / 'metadata.yaml'
    try:
        info = yaml.safe_load(metadata.read_text())['rosbag2_bagfile_information']
        return {
            str(t['topic_metadata']['name']): int(t['message_count'])
            for t in info['topics_with_message_count']
        }
    except (OSError, yaml.YAMLError, KeyError, TypeError, AttributeError, ValueError):
        return {}


def topic_types(files: list[Path]) -> dict[str, str]:
    """``{topic name: message type}`` over the ``topics`` tables of the databases.

    Raises
    ------
    apsw.Error
        A file is not a rosbag2 database.

    """
    topics: dict[str, str] = {}
    for db in files:
        connection = _connect(db)
        try:
            for name, msgtype in connection.execute('SELECT name, type FROM topics'):
                topics.setdefault(str(name), str(msgtype))
        finally:
            connection.close()
    return topics


def _connect(db: str | Path) -> apsw.Connection:
    """Read-only, immutable connection (no locking, no journal)."""
    uri = f'file:{Path(db).resolve()}?immutable=1'
    return apsw.Connection(uri, flags=apsw.SQLITE_OPEN_READONLY | apsw.SQLITE_OPEN_URI)


@contextmanager
def _gc_paused() -> Iterator[None]:
    """Pause the cyclic garbage collector (row tuples would trigger needless collections)."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def scan_sqlite(
    db: str | Path,
    topics: dict[str, str],
    *,
    log_times: bool = True,
    batch_size: int = 10_000,
) -> Iterator[Batch]:
    """Raw messages of some topics of one rosbag2 ``.db3`` file, topic by topic.

    Parameters
    ----------
    db : str or Path
        The database file.
    topics : dict of str to str
        Topic name -> message type (``sensor_msgs/msg/Imu``): only rows of topics with that
        name and type are read.
    log_times : bool, optional
        Also return the log (receive) times; False skips that column (a little faster).
    batch_size : int, optional
        Messages per batch.

    Yields
    ------
    topic : str
        The topic of this batch; all of one topic's batches come before the next topic's.
    log_times_ns : ndarray of int64, shape (N,), or None
        Log times in ns (None when ``log_times`` is false).
    payloads : list of bytes, length N
        Raw CDR messages, ordered by log time (with rosbags' query, so in its order).

    Raises
    ------
    apsw.Error
        The file is not a rosbag2 database or is damaged.

    """
    connection = _connect(db)
    try:
        for topic, msgtype in topics.items():
            ids = [
                row[0]
                for row in connection.execute(
                    'SELECT id FROM topics WHERE name = ? AND type = ?', (topic, msgtype)
                )
            ]
            if not ids:
                continue
            marks = ','.join('?' * len(ids))
            columns = 'timestamp, data' if log_times else 'data'
            cursor = connection.execute(
                f'SELECT {columns} FROM messages WHERE topic_id IN ({marks}) ORDER BY timestamp',
                ids,
            )
            while True:
                times, payloads = _fetch(cursor, batch_size, log_times)
                if not payloads:
                    break
                yield topic, times, payloads
    finally:
        connection.close()


def nth_log_time(db: str | Path, topic: str, msgtype: str, n: int) -> int | None:
    """Log time (ns) of a topic's ``n``-th message (1-based, by log time); None if unreadable.

    Where :func:`scan_sqlite` stopped on a damaged file: rows up to this time were read.
    """
    try:
        connection = _connect(db)
        try:
            rows = list(
                connection.execute(
                    'SELECT m.timestamp FROM messages m JOIN topics t ON m.topic_id = t.id '
                    'WHERE t.name = ? AND t.type = ? ORDER BY m.timestamp LIMIT 1 OFFSET ?',
                    (topic, msgtype, n - 1),
                )
            )
        finally:
            connection.close()
    except apsw.Error:
        return None
    return int(rows[0][0]) if rows and n > 0 else None


def _fetch(
    cursor: Any, size: int, log_times: bool
) -> tuple[NDArray[np.int64] | None, list[bytes]]:
    """Up to ``size`` rows of ``cursor`` as (log times or None, payloads)."""
    with _gc_paused():
        rows = list(islice(cursor, size))
        if not rows:
            return None, []
        if log_times:
            stamps, data = zip(*rows, strict=True)
            del rows
            return np.array(stamps, dtype=np.int64), list(data)
        payloads = [row[0] for row in rows]
        del rows
        return None, payloads
