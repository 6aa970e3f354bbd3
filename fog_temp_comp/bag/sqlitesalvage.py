"""Read the rows a damaged rosbag2 sqlite3 file still holds, page by page, without SQLite.

A recorder killed mid-run or a copy cut short leaves a ``.db3`` whose b-tree pages past the
cut are gone; SQLite then refuses every query ("database disk image is malformed"), because the
interior pages of a growing table are allocated late in the file. The leaf pages before the cut
are intact, and each holds whole rows. :func:`salvage_rows` walks the file's pages, parses the
table-leaf pages (SQLite file format, section 1.6) and keeps the rows shaped like rosbag2's
``messages`` (``NULL, topic_id, timestamp, data``) and ``topics`` (``NULL, name, type, ...``)
tables; a row whose overflow pages are missing is dropped. Rows come in file order, batched,
each batch sorted by timestamp.
"""

from __future__ import annotations

import mmap
import os
import struct
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

__all__ = ['SqliteDamage', 'expected_pages', 'salvage_rows', 'salvage_topics']

_LEAF_TABLE = 0x0D
_INTERIOR_TABLE = 0x05
_MAGIC = b'SQLite format 3\x00'


@dataclass
class SqliteDamage:
    """What :func:`salvage_rows` found: pages present, expected and unreadable, rows dropped."""

    pages_present: int = 0
    pages_expected: int = 0
    dropped_rows: int = 0
    #: newest timestamp (ns) of the rows on whole pages: rows lost from a cut page are newer
    newest_whole_ns: int = 0


def expected_pages(db: str | Path) -> tuple[int, int]:
    """(page size in bytes, page count the header promises); (0, 0) if not a SQLite file."""
    with Path(db).open('rb') as file:
        head = file.read(100)
    if len(head) < 100 or not head.startswith(_MAGIC):
        return 0, 0
    size = struct.unpack_from('>H', head, 16)[0]
    size = 65536 if size == 1 else size
    count = struct.unpack_from('>I', head, 28)[0]
    return size, count


def _varint(buf: bytes, pos: int) -> tuple[int, int]:
    """SQLite varint at ``pos``: (value, next position)."""
    value = 0
    for i in range(8):
        byte = buf[pos + i]
        value = (value << 7) | (byte & 0x7F)
        if byte < 0x80:
            return value, pos + i + 1
    return (value << 8) | buf[pos + 8], pos + 9


_INT_SIZES = {1: 1, 2: 2, 3: 3, 4: 4, 5: 6, 6: 8}


def _record(payload: bytes) -> list[object] | None:
    """Values of a record (ints, bytes for blob and text, None); None if malformed."""
    try:
        header_size, pos = _varint(payload, 0)
        types = []
        while pos < header_size:
            serial, pos = _varint(payload, pos)
            types.append(serial)
        pos = header_size
        values: list[object] = []
        for serial in types:
            if serial in (0, 8, 9):
                values.append(None if serial == 0 else serial - 8)
            elif serial in _INT_SIZES:
                n = _INT_SIZES[serial]
                values.append(int.from_bytes(payload[pos : pos + n], 'big', signed=True))
                pos += n
            elif serial == 7:
                values.append(struct.unpack_from('>d', payload, pos)[0])
                pos += 8
            elif serial >= 12:
                n = (serial - 12) // 2
                values.append(bytes(payload[pos : pos + n]))
                pos += n
            else:
                return None
        if pos > len(payload):
            return None
        return values
    except IndexError:
        return None


class _Pages:
    """The pages of a (possibly cut) SQLite file."""

    def __init__(self, data: bytes | mmap.mmap) -> None:
        size = struct.unpack_from('>H', data, 16)[0]
        self.size = 65536 if size == 1 else size
        self.usable = self.size - data[20]
        self.data = data
        self.whole = len(data) // self.size  # whole pages
        self.count = -(-len(data) // self.size)  # and the cut one, if any

    def page(self, number: int) -> bytes | None:
        """Page ``number`` (1-based; the last may be cut short), or None past the end."""
        if not 1 <= number <= self.count:
            return None
        return self.data[(number - 1) * self.size : number * self.size]

    def cells(self, number: int) -> Iterator[tuple[int, bytes] | None]:
        """(rowid, payload) of the cells of a table-leaf page (None for an unreadable cell)."""
        page = self.page(number)
        base = 100 if number == 1 else 0
        if page is None or len(page) < base + 8 or page[base] != _LEAF_TABLE:
            return
        ncells = struct.unpack_from('>H', page, base + 3)[0]
        usable = self.usable
        x = usable - 35
        m = ((usable - 12) * 32 // 255) - 23
        for k in range(ncells):
            try:
                at = struct.unpack_from('>H', page, base + 8 + 2 * k)[0]
                size, pos = _varint(page, at)
                rowid, pos = _varint(page, pos)
                if size <= x:  # (a cell of a cut page may lie before the cut)
                    payload = page[pos : pos + size]
                    yield (rowid, payload) if len(payload) == size else None
                    continue
                local = m + (size - m) % (usable - 4)
                local = local if local <= x else m
                parts = [page[pos : pos + local]]
                nxt = struct.unpack_from('>I', page, pos + local)[0]
                got = local
                while got < size:
                    over = self.page(nxt)
                    if over is None:
                        break
                    parts.append(over[4 : 4 + min(usable - 4, size - got)])
                    got += len(parts[-1])
                    nxt = struct.unpack_from('>I', over, 0)[0]
                payload = b''.join(parts)
                yield (rowid, payload) if len(payload) == size else None
            except (struct.error, IndexError):
                yield None


@contextmanager
def _mapped(db: str | Path) -> Iterator[bytes | mmap.mmap]:
    """The file's bytes, memory-mapped (a 24 h bag is gigabytes); b'' if empty."""
    with Path(db).open('rb') as file:
        if not os.fstat(file.fileno()).st_size:
            yield b''
            return
        with mmap.mmap(file.fileno(), 0, access=mmap.ACCESS_READ) as data:
            yield data


def salvage_topics(db: str | Path) -> dict[int, tuple[str, str]]:
    """``{topic id: (name, type)}`` from the ``topics`` rows still in the file.

    The ``topics`` table is found through the schema on page 1 (a page or two); if that is
    unreadable, every page is searched.
    """
    with _mapped(db) as data:
        if len(data) < 100 or data[:16] != _MAGIC:
            return {}
        pages = _Pages(data)
        root = _root_page(pages, b'topics')
        found = _topic_rows(pages, _table_pages(pages, root)) if root else {}
        return found or _topic_rows(pages, range(1, pages.count + 1))


def _root_page(pages: _Pages, table: bytes) -> int | None:
    """Root page of ``table`` from ``sqlite_master`` (page 1, if it is a leaf), or None."""
    for cell in pages.cells(1):
        values = _record(cell[1]) if cell is not None else None
        if values and len(values) >= 4 and values[0] == b'table' and values[1] == table:
            root = values[3]
            return root if isinstance(root, int) and root > 0 else None
    return None


def _table_pages(pages: _Pages, root: int) -> list[int]:
    """The leaf pages of the table b-tree at ``root`` that are in the file."""
    leaves, todo, seen = [], [root], set()
    while todo:
        number = todo.pop()
        page = pages.page(number)
        if number in seen or page is None or len(page) < 12:
            continue
        seen.add(number)
        if page[0] == _LEAF_TABLE:
            leaves.append(number)
        elif page[0] == _INTERIOR_TABLE:
            ncells = struct.unpack_from('>H', page, 3)[0]
            todo.append(struct.unpack_from('>I', page, 8)[0])
            for k in range(ncells):
                if 12 + 2 * k + 2 > len(page):
                    break
                at = struct.unpack_from('>H', page, 12 + 2 * k)[0]
                if at + 4 <= len(page):
                    todo.append(struct.unpack_from('>I', page, at)[0])
    return sorted(leaves)


def _topic_rows(pages: _Pages, numbers: Iterable[int]) -> dict[int, tuple[str, str]]:
    topics: dict[int, tuple[str, str]] = {}
    for number in numbers:
        for cell in pages.cells(number):
            if cell is None:
                continue
            row = _topic_row(_record(cell[1]))
            if row is not None:
                topics.setdefault(cell[0], row)
    return topics


def _topic_row(values: list[object] | None) -> tuple[str, str] | None:
    """(name, type) of a ``topics`` row (``NULL, name, type, format, qos, ...``), else None."""
    if values is None or len(values) < 5 or values[0] is not None:
        return None
    name, msgtype = values[1], values[2]
    if not all(isinstance(v, bytes) for v in values[1:5]):
        return None
    assert isinstance(name, bytes) and isinstance(msgtype, bytes)
    if not name.startswith(b'/') or b'/' not in msgtype:
        return None
    try:
        return name.decode(), msgtype.decode()
    except UnicodeDecodeError:
        return None


def salvage_rows(
    db: str | Path,
    topic_ids: dict[int, str],
    *,
    batch_size: int = 10_000,
    damage: SqliteDamage | None = None,
) -> Iterator[tuple[str, NDArray[np.int64], list[bytes]]]:
    """The ``messages`` rows of some topics still readable in a damaged ``.db3``.

    Parameters
    ----------
    db : str or Path
        The database file (possibly cut or with damaged pages).
    topic_ids : dict of int to str
        ``topics.id`` -> topic name of the rows to return.
    batch_size : int, optional
        Rows per batch (and topic).
    damage : SqliteDamage, optional
        Filled with the pages present and expected, and the rows dropped.

    Yields
    ------
    topic : str
    log_times_ns : ndarray of int64, shape (N,)
        Receive times (``timestamp`` column), sorted within the batch.
    payloads : list of bytes, length N
        Raw CDR messages.

    """
    damage = damage if damage is not None else SqliteDamage()
    with _mapped(db) as data:
        if len(data) >= 100 and data[:16] == _MAGIC:
            yield from _rows(_Pages(data), topic_ids, batch_size, damage)


def _rows(
    pages: _Pages, topic_ids: dict[int, str], batch_size: int, damage: SqliteDamage
) -> Iterator[tuple[str, NDArray[np.int64], list[bytes]]]:
    """:func:`salvage_rows` on the pages of an open file."""
    data = pages.data
    damage.pages_present = pages.whole
    damage.pages_expected = max(struct.unpack_from('>I', data, 28)[0], pages.count)
    pending: dict[str, tuple[list[int], list[bytes]]] = {}
    seen: set[int] = set()
    for number in range(1, pages.count + 1):
        for cell in pages.cells(number):
            if cell is None:
                damage.dropped_rows += 1
                continue
            rowid, payload = cell
            values = _record(payload)
            if (
                values is None
                or len(values) != 4
                or values[0] is not None
                or not isinstance(values[1], int)
                or not isinstance(values[2], int)
                or not isinstance(values[3], bytes)
            ):
                continue
            topic = topic_ids.get(values[1])
            if topic is None or rowid in seen:
                continue
            seen.add(rowid)
            if number <= pages.whole:
                damage.newest_whole_ns = max(damage.newest_whole_ns, values[2])
            times, raws = pending.setdefault(topic, ([], []))
            times.append(values[2])
            raws.append(values[3])
            if len(raws) >= batch_size:
                yield _batch(topic, times, raws)
                pending[topic] = ([], [])
    for topic, (times, raws) in pending.items():
        if raws:
            yield _batch(topic, times, raws)


def _batch(
    topic: str, times: list[int], raws: list[bytes]
) -> tuple[str, NDArray[np.int64], list[bytes]]:
    t = np.array(times, dtype=np.int64)
    order = np.argsort(t, kind='stable')
    return topic, t[order], [raws[k] for k in order.tolist()]
