"""Fast raw reading of ROS 1 bags (format 2.0), without a Python object per message.

rosbags' ROS 1 reader builds a Python object for every index entry when it opens a bag and
another per message when it reads. :class:`Ros1Bag` reads the connections and chunk infos from
the bag's index section, and :meth:`Ros1Bag.scan` reads a chunk at a time: the ``IDXDATA``
records after each chunk give every message's time and offset (``np.frombuffer``), and the
message records are checked and located with numpy. The payloads go to the decoders of
:mod:`fog_temp_comp.bag.cdr` as :class:`~fog_temp_comp.bag.cdr.Spans`.

A chunk whose message records do not all share the first one's header layout (legal, but not
what ``rosbag`` or rosbags write) is read record by record instead. A bag this module cannot
read at all (not indexed, encrypted, unknown compression, several connections on one wanted
topic) raises :class:`Ros1FormatError` from the constructor, before anything is returned.

Given a :class:`~fog_temp_comp.bag.salvage.Salvage`, a bag whose index is missing (never
indexed: the recorder was killed) or cut off is walked record by record instead: chunks and
connections are found in the data section, a damaged chunk is skipped, the chunk the file ends
in is read up to its last whole message (uncompressed chunks), and the damage is recorded.

Order: chunks in file order; within a chunk, messages stable-sorted by time (as with MCAP).
"""

from __future__ import annotations

import bz2
import struct
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.bag.cdr import Spans
from fog_temp_comp.bag.salvage import Salvage

try:
    from lz4.frame import decompress as _lz4_decompress
except ImportError:  # pragma: no cover
    _lz4_decompress = None

__all__ = ['Ros1Bag', 'Ros1Connection', 'Ros1FormatError']

IntArray = NDArray[np.int64]
MAGIC = b'#ROSBAG V2.0\n'
_OP_MSG_DATA = 0x02
_OP_BAG_HEADER = 0x03
_OP_INDEX_DATA = 0x04
_OP_CHUNK = 0x05
_OP_CHUNK_INFO = 0x06
_OP_CONNECTION = 0x07
_INDEX_ENTRY = np.dtype([('sec', '<u4'), ('nsec', '<u4'), ('offset', '<u4')])
_U32 = struct.Struct('<I')


class Ros1FormatError(ValueError):
    """The bag is not one this reader handles; read it with rosbags instead."""


#: what a damaged chunk raises (record parsing, lz4, bz2)
_DAMAGE = (Ros1FormatError, KeyError, ValueError, OSError, struct.error, RuntimeError, EOFError)


@dataclass(frozen=True)
class Ros1Connection:
    """A connection of the bag: id, topic, message type (``pkg/msg/Name``), definition, MD5."""

    id: int
    topic: str
    msgtype: str
    msgdef: str
    md5sum: str = ''


def _fields(header: bytes) -> dict[str, bytes]:
    """The ``name=value`` fields of a record header."""
    out: dict[str, bytes] = {}
    pos = 0
    while pos + 4 <= len(header):
        size = _U32.unpack_from(header, pos)[0]
        name, sep, value = header[pos + 4 : pos + 4 + size].partition(b'=')
        if not sep or pos + 4 + size > len(header):
            raise Ros1FormatError('malformed ROS 1 record header')
        out[name.decode()] = value
        pos += 4 + size
    return out


def _connection(fields: dict[str, bytes], info: dict[str, bytes]) -> Ros1Connection:
    """A connection from its record's header and data fields."""
    return Ros1Connection(
        _U32.unpack(fields['conn'])[0],
        '/' + fields['topic'].decode().lstrip('/'),
        _msgtype(info['type'].decode()),
        info.get('message_definition', b'').decode(),
        info.get('md5sum', b'').decode(),
    )


def _inner_records(records: bytes) -> Iterator[tuple[dict[str, bytes], int, int]]:
    """(header fields, data offset, data length) of the whole records in a chunk's data."""
    pos = 0
    while pos + 4 <= len(records):
        hlen = _U32.unpack_from(records, pos)[0]
        if pos + 8 + hlen > len(records):
            return
        fields = _fields(records[pos + 4 : pos + 4 + hlen])
        at = pos + 8 + hlen
        dlen = _U32.unpack_from(records, at - 4)[0]
        if at + dlen > len(records):
            return
        yield fields, at, dlen
        pos = at + dlen


def _inner_connections(records: bytes) -> Iterator[Ros1Connection]:
    """The Connection records inside a chunk's data."""
    for fields, at, dlen in _inner_records(records):
        if fields.get('op') == bytes([_OP_CONNECTION]):
            yield _connection(fields, _fields(records[at : at + dlen]))


def _msgtype(name: str) -> str:
    """``pkg/Name`` as rosbags names it, ``pkg/msg/Name``."""
    package, _, message = name.rpartition('/')
    return name if package.endswith('/msg') else f'{package}/msg/{message}'


def _decompressor(name: str) -> Callable[[bytes], bytes]:
    if name == 'none':
        return lambda data: data
    if name == 'bz2':
        return bz2.decompress
    if name == 'lz4' and _lz4_decompress is not None:
        return _lz4_decompress
    raise Ros1FormatError(f'unsupported ROS 1 chunk compression {name!r}')


class Ros1Bag:
    """An indexed ROS 1 bag: its connections, and a fast scan of chosen topics.

    Parameters
    ----------
    path : str or Path
        The ``.bag`` file.

    Raises
    ------
    Ros1FormatError
        Not a ROS 1 bag of format 2.0, not indexed, encrypted, or damaged index.

    """

    def __init__(self, path: str | Path, salvage: Salvage | None = None) -> None:
        self.path = Path(path)
        self.salvage = salvage
        self.connections: list[Ros1Connection] = []
        self.chunk_positions: list[int] = []
        self.walked = False  # chunks found by walking the data section (no usable index)
        #: chunk position -> {connection id: message count}, from the index's chunk infos
        self.chunk_counts: dict[int, dict[int, int]] = {}
        with self.path.open('rb') as file:
            if file.read(len(MAGIC)) != MAGIC:
                raise Ros1FormatError(f'{self.path}: not a ROS 1 bag of format 2.0')
            header, _ = self._record(file)
            self._data_start = file.tell()
            fields = _fields(header)
            if fields.get('op') != bytes([_OP_BAG_HEADER]):
                raise Ros1FormatError(f'{self.path}: no bag header record')
            if fields.get('encryptor'):
                raise Ros1FormatError(f'{self.path}: encrypted bag')
            try:
                self._read_index(file, fields)
            except (Ros1FormatError, KeyError, struct.error, UnicodeDecodeError) as err:
                if salvage is None:
                    if isinstance(err, Ros1FormatError):
                        raise
                    raise Ros1FormatError(f'{self.path}: damaged index ({err})') from err
                self.connections, self.chunk_positions = [], []
                reason = 'never indexed' if fields.get('index_pos') == bytes(8) else 'index lost'
                salvage.damage(f'{reason} (recorder killed or file cut?): chunks read in order')
                self._walk(file)

    def _read_index(self, file: BinaryIO, fields: dict[str, bytes]) -> None:
        """Connections and chunk positions from the index section."""
        index_pos = struct.unpack('<Q', fields['index_pos'])[0]
        conn_count = _U32.unpack(fields['conn_count'])[0]
        chunk_count = _U32.unpack(fields['chunk_count'])[0]
        if index_pos == 0:
            raise Ros1FormatError(f'{self.path}: bag is not indexed')
        file.seek(index_pos)
        for _ in range(conn_count):
            header, data = self._record(file)
            fields = _fields(header)
            info = _fields(data)
            if fields.get('op') != bytes([_OP_CONNECTION]):
                raise Ros1FormatError(f'{self.path}: damaged connection records')
            self.connections.append(_connection(fields, info))
        for _ in range(chunk_count):
            header, data = self._record(file)
            fields = _fields(header)
            if fields.get('op') != bytes([_OP_CHUNK_INFO]):
                raise Ros1FormatError(f'{self.path}: damaged chunk info records')
            position = struct.unpack('<Q', fields['chunk_pos'])[0]
            self.chunk_positions.append(position)
            pairs = np.frombuffer(data[: len(data) // 8 * 8], dtype='<u4').reshape(-1, 2)
            self.chunk_counts[position] = {int(c): int(n) for c, n in pairs.tolist()}

    def _walk(self, file: BinaryIO) -> None:
        """Find chunks and connections in the data section (no index); records the damage."""
        self.walked = True
        size = file.seek(0, 2)
        pos = self._data_start
        known: set[int] = set()
        while pos < size:
            record = self._head(file, pos, size)
            if record is None:
                found = self._next_chunk(file, pos + 1, size)
                if found is None:
                    self._cut_at(pos, size)
                    return
                assert self.salvage is not None
                self.salvage.damage(
                    f'unreadable records at bytes {pos}-{found}', skipped_bytes=found - pos
                )
                pos = found
                continue
            fields, data_at, data_len = record
            op = fields.get('op', b'')
            nxt = data_at + data_len
            if op == bytes([_OP_CHUNK]):
                if nxt > size:  # the file ends inside this chunk: its whole records
                    self.chunk_positions.append(pos)
                    if fields.get('compression') == b'none':
                        file.seek(data_at)
                        for conn in _inner_connections(file.read(size - data_at)):
                            if conn.id not in known:
                                known.add(conn.id)
                                self.connections.append(conn)
                    return
                self.chunk_positions.append(pos)
                conns, after = self._index_conns(file, nxt, size)
                if not conns or not conns <= known:
                    try:
                        file.seek(data_at)
                        records = _decompressor(fields['compression'].decode())(
                            file.read(data_len)
                        )
                        for conn in _inner_connections(records):
                            if conn.id not in known:
                                known.add(conn.id)
                                self.connections.append(conn)
                    except _DAMAGE:
                        pass  # scan() skips and records the damaged chunk
                nxt = after
            elif op == bytes([_OP_CONNECTION]) and nxt <= size:
                file.seek(data_at)
                conn = _connection(fields, _fields(file.read(data_len)))
                if conn.id not in known:
                    known.add(conn.id)
                    self.connections.append(conn)
            elif nxt > size:
                self._cut_at(pos, size)
                return
            pos = nxt

    def _cut_at(self, pos: int, size: int) -> None:
        assert self.salvage is not None
        if size > pos:
            self.salvage.damage(
                f'the file ends at byte {size} inside a record at byte {pos}',
                skipped_bytes=size - pos,
            )

    def _head(
        self, file: BinaryIO, pos: int, size: int
    ) -> tuple[dict[str, bytes], int, int] | None:
        """(header fields, data offset, data length) of the record at ``pos``, or None."""
        file.seek(pos)
        raw = file.read(4)
        if len(raw) < 4:
            return None
        hlen = _U32.unpack(raw)[0]
        if pos + 8 + hlen > size or hlen > 1 << 20:
            return None
        header = file.read(hlen)
        raw = file.read(4)
        try:
            fields = _fields(header)
        except (Ros1FormatError, UnicodeDecodeError):
            return None
        if len(raw) < 4 or not fields.get('op'):
            return None
        return fields, pos + 8 + hlen, _U32.unpack(raw)[0]

    def _index_conns(self, file: BinaryIO, pos: int, size: int) -> tuple[set[int], int]:
        """Connection ids of the IDXDATA records at ``pos`` and the offset after them."""
        conns: set[int] = set()
        while True:
            record = self._head(file, pos, size)
            if record is None or record[0].get('op') != bytes([_OP_INDEX_DATA]):
                return conns, pos
            fields, data_at, data_len = record
            if data_at + data_len > size or len(fields.get('conn', b'')) != 4:
                return conns, pos
            conns.add(_U32.unpack(fields['conn'])[0])
            pos = data_at + data_len

    def _next_chunk(self, file: BinaryIO, pos: int, size: int) -> int | None:
        """Offset of the next whole Chunk record from ``pos`` on (found by its fields)."""
        file.seek(pos)
        data = file.read(size - pos)
        at = data.find(b'op=\x05')
        while at >= 0:
            for start in range(max(at - 64, 0), at):
                record = self._head(file, pos + start, size)
                if (
                    record is not None
                    and record[0].get('op') == bytes([_OP_CHUNK])
                    and record[1] + record[2] <= size
                    and 'compression' in record[0]
                ):
                    return pos + start
            at = data.find(b'op=\x05', at + 1)
        return None

    def _record(self, file: BinaryIO) -> tuple[bytes, bytes]:
        """(header, data) of the record at the file's position."""
        try:
            header = file.read(_U32.unpack(file.read(4))[0])
            data = file.read(_U32.unpack(file.read(4))[0])
        except struct.error:
            raise Ros1FormatError(f'{self.path}: truncated record') from None
        return header, data

    def topics(self) -> dict[str, str]:
        """``{topic: message type}`` (the first connection's type for a topic)."""
        out: dict[str, str] = {}
        for conn in self.connections:
            out.setdefault(conn.topic, conn.msgtype)
        return out

    def scan(self, topics: set[str]) -> Iterator[tuple[str, IntArray, Spans]]:
        """Per chunk and wanted topic: (topic, times ns, spans of the message data)."""
        conns = {c.id: c.topic for c in self.connections if c.topic in topics}
        for topic in set(conns.values()):
            if list(conns.values()).count(topic) > 1:
                raise Ros1FormatError(f'{self.path}: several connections on {topic}')
        gap_from: int | None = None  # newest time before a skipped chunk (ns)
        newest = 0
        with self.path.open('rb') as file:
            size = file.seek(0, 2)
            for position in self.chunk_positions:
                try:
                    batches = list(self._chunk(file, position, size, conns))
                except _DAMAGE as err:
                    if self.salvage is None:
                        raise
                    end = min(self._chunk_end(file, position, size), size)
                    counts = self._lost_counts(file, position, size)
                    self.salvage.damage(
                        f'damaged chunk at byte {position} ({err})',
                        skipped_bytes=end - position,
                        chunks=1,
                        lost_messages=None
                        if counts is None
                        else sum(n for c, n in counts.items() if c in conns),
                    )
                    gap_from = newest if gap_from is None else gap_from
                    continue
                for batch in batches:
                    if gap_from is not None and self.salvage is not None and batch[1].size:
                        self.salvage.gaps_ns.append((gap_from, int(batch[1].min())))
                        gap_from = None
                    if batch[1].size:
                        newest = max(newest, int(batch[1].max()))
                    yield batch
        if gap_from is not None and self.salvage is not None:
            self.salvage.gaps_ns.append((gap_from, None))

    def _lost_counts(self, file: BinaryIO, position: int, size: int) -> dict[int, int] | None:
        """Messages per connection in the chunk at ``position`` (None: not known).

        From the index's chunk info, else from the ``IDXDATA`` records after the chunk.
        """
        if position in self.chunk_counts:
            return self.chunk_counts[position]
        record = self._head(file, position, size)
        if record is None or record[1] + record[2] > size:
            return None
        counts: dict[int, int] = {}
        pos = record[1] + record[2]
        while (head := self._head(file, pos, size)) is not None:
            fields, body_at, body_len = head
            if fields.get('op') != bytes([_OP_INDEX_DATA]) or body_at + body_len > size:
                break
            if len(fields.get('conn', b'')) != 4 or len(fields.get('count', b'')) != 4:
                return None
            conn, count = _U32.unpack(fields['conn'])[0], _U32.unpack(fields['count'])[0]
            counts[conn] = counts.get(conn, 0) + count
            pos = body_at + body_len
        return counts or None

    def _chunk_end(self, file: BinaryIO, position: int, size: int) -> int:
        """Offset after the chunk record at ``position`` and its IDXDATA records."""
        record = self._head(file, position, size)
        if record is None:
            return size
        return self._index_conns(file, record[1] + record[2], size)[1]

    def _chunk(
        self, file: BinaryIO, position: int, size: int, conns: dict[int, str]
    ) -> Iterator[tuple[str, IntArray, Spans]]:
        """The wanted messages of the chunk at ``position`` (cut chunks: the whole records)."""
        file.seek(position)
        record = self._head(file, position, size)
        if record is None or record[0].get('op') != bytes([_OP_CHUNK]):
            raise Ros1FormatError(f'{self.path}: no chunk at byte {position}')
        fields, data_at, data_len = record
        if data_at + data_len > size:  # the file ends inside this chunk
            if self.salvage is None or fields.get('compression') != b'none':
                raise Ros1FormatError(f'{self.path}: the file ends inside the chunk')
            file.seek(data_at)
            records = file.read(size - data_at)
            batches = list(self._walk_messages(records, conns))
            used = max((int(sp.starts.max() + sp.lengths[sp.starts.argmax()])
                        for _, _, sp in batches), default=0)  # fmt: skip
            self.salvage.damage(
                f'the file ends at byte {size} inside the chunk at byte {position}',
                skipped_bytes=size - data_at - used,
                gap_ns=(max((int(t.max()) for _, t, _ in batches), default=0), None),
            )
            yield from batches
            return
        file.seek(data_at)
        records = _decompressor(fields['compression'].decode())(file.read(data_len))
        indexes: dict[int, NDArray[np.void]] = {}
        pos = data_at + data_len
        cut_index = False  # an IDXDATA record the file ends in: walk the chunk instead
        while True:
            head = self._head(file, pos, size)
            if head is None or head[0].get('op') != bytes([_OP_INDEX_DATA]):
                cut_index = head is None and self.walked and pos < size
                break
            ifields, body_at, body_len = head
            if body_at + body_len > size:
                cut_index = True
                break
            file.seek(body_at)
            body = file.read(body_len)
            conn = _U32.unpack(ifields['conn'])[0]
            if conn in conns:
                indexes[conn] = np.frombuffer(body, dtype=_INDEX_ENTRY)
            pos = body_at + body_len
        if self.salvage is not None and (cut_index or (not indexes and self.walked)):
            yield from self._walk_messages(records, conns)
            return
        try:
            batches = [
                batch
                for conn, entries in indexes.items()
                for batch in self._messages(records, conns[conn], conn, entries)
            ]
        except Ros1FormatError as err:
            if self.salvage is None:
                raise
            self.salvage.damage(f'chunk at byte {position}: damaged index ({err}); walked')
            batches = list(self._walk_messages(records, conns))
        yield from batches

    def _walk_messages(
        self, records: bytes, conns: dict[int, str]
    ) -> Iterator[tuple[str, IntArray, Spans]]:
        """The wanted messages of a chunk's data, record by record (no index)."""
        found: dict[int, tuple[list[int], list[int], list[int]]] = {}
        for fields, at, dlen in _inner_records(records):
            if fields.get('op') != bytes([_OP_MSG_DATA]):
                continue
            conn = _U32.unpack(fields.get('conn', b'\xff' * 4))[0]
            if conn in conns:
                sec, nsec = struct.unpack('<II', fields.get('time', bytes(8)))
                times, starts, lengths = found.setdefault(conn, ([], [], []))
                times.append(sec * 1_000_000_000 + nsec)
                starts.append(at)
                lengths.append(dlen)
        for conn, (times, starts, lengths) in found.items():
            t = np.array(times, dtype=np.int64)
            order = np.argsort(t, kind='stable')
            spans = Spans(records, np.array(starts, np.int64)[order], np.array(lengths)[order])
            yield conns[conn], t[order], spans

    def _messages(
        self, records: bytes, topic: str, conn: int, entries: NDArray[np.void]
    ) -> Iterator[tuple[str, IntArray, Spans]]:
        """The messages of one connection in one chunk, located through its index entries."""
        if entries.size == 0:
            return
        times = entries['sec'].astype(np.int64) * 1_000_000_000 + entries['nsec']
        offsets = entries['offset'].astype(np.int64)
        starts, lengths = self._locate(records, offsets, conn, times)
        order = np.argsort(times, kind='stable')
        yield topic, times[order], Spans(records, starts[order], lengths[order])

    def _locate(
        self, records: bytes, offsets: IntArray, conn: int, times: IntArray
    ) -> tuple[IntArray, IntArray]:
        """Data start and length of the message records at ``offsets``, checked.

        Fast path: every record's header has the first one's layout (fields, order, sizes), so
        the conn and time values sit at the same places; checked with numpy. Otherwise each
        record is parsed in Python.
        """
        size = len(records)
        buf = np.frombuffer(records, dtype=np.uint8)
        if offsets.min() < 0 or offsets.max() + 4 > size:
            raise Ros1FormatError(f'{self.path}: index offset outside its chunk')
        first = int(offsets[0])
        header_len = _U32.unpack_from(records, first)[0]
        layout = _header_layout(records[first + 4 : first + 4 + header_len])
        if layout is not None and offsets.max() + 8 + header_len <= size:
            head = buf[offsets[:, None] + 4 + np.arange(header_len)]
            same_len = _le(buf[offsets[:, None] + np.arange(4)], 0, 4) == header_len
            mask, conn_at, time_at = layout
            template = np.frombuffer(records[first + 4 : first + 4 + header_len], np.uint8)
            same = same_len & (head[:, mask] == template[mask]).all(axis=1)
            conn_ok = _le(head, conn_at, 4) == conn
            time_ok = (_le(head, time_at, 4) * 1_000_000_000 + _le(head, time_at + 4, 4)) == (
                times
            )
            if bool((same & conn_ok & time_ok).all()):
                at = offsets + 4 + header_len
                data_len = _le(buf[at[:, None] + np.arange(4)], 0, 4)
                starts = at + 4
                if bool((starts + data_len <= size).all()):
                    return starts, data_len
        return self._locate_slowly(records, offsets, conn, times)

    def _locate_slowly(
        self, records: bytes, offsets: IntArray, conn: int, times: IntArray
    ) -> tuple[IntArray, IntArray]:
        """:meth:`_locate` one record at a time (any header layout)."""
        starts, lengths = [], []
        for offset, time in zip(offsets.tolist(), times.tolist(), strict=True):
            header_len = _U32.unpack_from(records, offset)[0]
            fields = _fields(records[offset + 4 : offset + 4 + header_len])
            at = offset + 4 + header_len
            data_len = _U32.unpack_from(records, at)[0]
            sec, nsec = struct.unpack('<II', fields.get('time', b'\0' * 8))
            if (
                fields.get('op') != bytes([_OP_MSG_DATA])
                or _U32.unpack(fields.get('conn', b'\xff' * 4))[0] != conn
                or sec * 1_000_000_000 + nsec != time
                or at + 4 + data_len > len(records)
            ):
                raise Ros1FormatError(f'{self.path}: index entry does not match its record')
            starts.append(at + 4)
            lengths.append(data_len)
        return np.array(starts, dtype=np.int64), np.array(lengths, dtype=np.int64)


def _le(rows: NDArray[np.uint8], at: int, size: int) -> IntArray:
    """Little-endian unsigned integers of ``size`` bytes at column ``at`` of byte rows."""
    out = np.zeros(rows.shape[0], dtype=np.int64)
    for j in reversed(range(size)):
        out = (out << 8) | rows[:, at + j]
    return out


def _header_layout(header: bytes) -> tuple[NDArray[np.bool_], int, int] | None:
    """For a message record header: (mask of its non-value bytes, conn value at, time at).

    None if it is not an ``op=2`` header with 4-byte ``conn`` and 8-byte ``time`` fields.
    """
    mask = np.ones(len(header), dtype=bool)
    where: dict[str, tuple[int, int]] = {}
    pos = 0
    while pos + 4 <= len(header):
        size = _U32.unpack_from(header, pos)[0]
        field = header[pos + 4 : pos + 4 + size]
        name, sep, value = field.partition(b'=')
        if not sep or pos + 4 + size > len(header):
            return None
        value_at = pos + 4 + len(name) + 1
        where[name.decode(errors='replace')] = (value_at, len(value))
        if name in (b'conn', b'time'):
            mask[value_at : value_at + len(value)] = False
        pos += 4 + size
    if pos != len(header) or where.get('conn', (0, 0))[1] != 4:
        return None
    if where.get('time', (0, 0))[1] != 8 or 'op' not in where:
        return None
    op_at = where['op'][0]
    if header[op_at : op_at + 1] != bytes([_OP_MSG_DATA]):
        return None
    return mask, where['conn'][0], where['time'][0]
