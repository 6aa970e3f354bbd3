"""Fast raw scanner for MCAP files (rosbag2's default storage), without per-message objects.

``rosbags``' ``AnyReader.messages()`` parses every MCAP record in Python and builds a tuple per
message; for the vectorised CDR decoders in :mod:`fog_temp_comp.bag.cdr` that is the bottleneck.
:func:`scan_mcap` yields, per chunk and topic, a log-time array and the messages' positions in
the (decompressed) chunk as :class:`fog_temp_comp.bag.cdr.Spans`, which the decoders read in place:

- **Indexed** (what rosbag2 and rosbags write): the Message Index records that follow each
  chunk give every message's log time and offset, read with ``np.frombuffer``; the records at
  those offsets are checked (opcode, channel, length, log time) with numpy. No Python code
  runs per message.
- **Walked** (no index, an index that does not match its chunk, or a channel first defined
  inside the chunk): the records are walked with :func:`struct.unpack_from` on one buffer.

Ordering: within one batch (a chunk, or the unchunked messages between chunks) messages are
stable-sorted by log time when ``sort_by_time`` is true (the default), else given in file order.
Batches are yielded in file order; they are not merged across chunks. For files whose chunks do
not overlap in time (what rosbags' and rosbag2's writers produce for time-ordered input) this is
the same sequence per topic as ``AnyReader.messages()``.
"""

from __future__ import annotations

import struct
import sys
import zlib
from collections.abc import Callable, Generator, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.bag.cdr import Spans
from fog_temp_comp.bag.salvage import Salvage

if sys.version_info >= (3, 14):
    from compression import zstd
else:  # pragma: no cover
    from backports import zstd

try:
    from lz4.frame import decompress as _lz4_decompress
except ImportError:  # pragma: no cover
    _lz4_decompress = None

__all__ = [
    'MAGIC',
    'ScanStats',
    'Spans',
    'check_counts',
    'chunk_offsets',
    'mcap_topics',
    'scan_mcap',
]

MAGIC = b'\x89MCAP0\r\n'

_OP_FOOTER = 0x02
_OP_SCHEMA = 0x03
_OP_CHANNEL = 0x04
_OP_MESSAGE = 0x05
_OP_CHUNK = 0x06
_OP_MESSAGE_INDEX = 0x07
_OP_CHUNK_INDEX = 0x08
_OP_STATISTICS = 0x0B

_HEADER = struct.Struct('<BQ')  # opcode, record length
_HEADER_MESSAGE = struct.Struct('<BQH4xQ')  # opcode, length, channel id, (sequence), log time
_MESSAGE_HEAD = 22  # channel id u16, sequence u32, log time u64, publish time u64
_CHANNEL = struct.Struct('<HHI')  # id, schema id, topic length
_CHUNK = struct.Struct('<16xQII')  # (start, end), uncompressed size, crc, compression length
_FOOTER = struct.Struct('<BQQQI')  # opcode, length, summary start, summary offset start, crc
_INDEX_HEAD = struct.Struct('<HI')  # channel id, byte length of the (log time, offset) array
_INDEX_ENTRY = np.dtype([('log_time', '<u8'), ('offset', '<u8')])
_U32 = struct.Struct('<I')
_U64 = struct.Struct('<Q')
_STATISTICS_HEAD = 42  # counts and times before the channel message counts
_CHANNEL_COUNT = struct.Struct('<HQ')  # channel id, message count

Batch = tuple[str, NDArray[np.int64], Spans]


@dataclass
class ScanStats:
    """How :func:`scan_mcap` read the chunks of a file (and, for a span, what it found)."""

    indexed_chunks: int = 0  # through their Message Index records
    walked_chunks: int = 0  # record by record
    #: messages yielded per topic
    yielded: dict[str, int] = field(default_factory=dict)
    #: messages per wanted topic in the file's Statistics record (None: no such record)
    expected: dict[str, int] | None = None
    #: messages lost in skipped chunks, counted from their indexes
    counted: int = 0
    #: newest log time yielded, ns
    last_log_ns: int = 0


def _decompress(name: str, data: memoryview, size: int) -> bytes:
    """Decompress a chunk's records with the named MCAP compression."""
    if name == 'zstd':
        out: bytes = zstd.decompress(data)
    elif name == 'lz4':
        if _lz4_decompress is None:  # pragma: no cover
            raise ValueError('MCAP chunk is lz4-compressed but the lz4 package is not installed')
        out = _lz4_decompress(bytes(data))
    else:
        raise ValueError(f'unsupported MCAP chunk compression {name!r}')
    if len(out) != size:
        raise ValueError(f'MCAP chunk decompressed to {len(out)} bytes, expected {size}')
    return out


def _at(buf: memoryview | bytes, positions: NDArray[np.int64], dtype: str) -> NDArray[np.int64]:
    """The little-endian integers of ``dtype`` at byte ``positions`` of ``buf`` (unaligned)."""
    size = np.dtype(dtype).itemsize
    every_byte = np.ndarray((len(buf) - size + 1,), dtype=dtype, buffer=buf, strides=(1,))
    return every_byte[positions].astype(np.int64)


class _Scanner:
    """State of one scan: channel map, per-topic collections of the current batch."""

    def __init__(self, path: Path, topics: set[str], sort_by_time: bool) -> None:
        self.path = path
        self.topics = topics
        self.sort_by_time = sort_by_time
        self.channel_topic: dict[int, str] = {}
        # channel id -> (log times, starts, lengths) lists of the current batch, wanted only
        self.wanted: dict[int, tuple[list[int], list[int], list[int]]] = {}
        self.collect: dict[str, tuple[list[int], list[int], list[int]]] = {}
        # (topic, log times, starts, lengths) of a chunk read through its indexes
        self.pending: list[
            tuple[str, NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]
        ] = []
        self.channel_counts: dict[int, int] | None = None  # from the Statistics record
        self.yielded: dict[str, int] = {}  # messages yielded per topic
        self.last_log_ns = 0  # newest log time yielded so far

    def discard(self) -> None:
        """Forget the current batch (its chunk turned out damaged)."""
        self.pending = []
        for times, starts, lengths in self.collect.values():
            times.clear()
            starts.clear()
            lengths.clear()

    def _error(self, what: str) -> ValueError:
        return ValueError(f'{self.path}: {what}')

    def channel(self, buf: memoryview, body: int, end: int) -> None:
        """Register a Channel record; route wanted topics to their collection."""
        if body + 8 > end:
            raise self._error('truncated MCAP channel record')
        cid, _schema, tlen = _CHANNEL.unpack_from(buf, body)
        if body + 8 + tlen > end:
            raise self._error('truncated MCAP channel record')
        topic = bytes(buf[body + 8 : body + 8 + tlen]).decode()
        if self.channel_topic.get(cid, topic) != topic:
            raise self._error(f'MCAP channel {cid} redefined as {topic!r}')
        self.channel_topic[cid] = topic
        if topic in self.topics and cid not in self.wanted:
            self.wanted[cid] = self.collect.setdefault(topic, ([], [], []))

    def summary_channels(self, summary: bytes) -> None:
        """Register the Channel records of a summary section (stops at a malformed record)."""
        buf = memoryview(summary)
        pos = 0
        while pos + 9 <= len(buf):
            op, length = _HEADER.unpack_from(buf, pos)
            nxt = pos + 9 + length
            if nxt > len(buf):
                return
            if op == _OP_CHANNEL:
                self.channel(buf, pos + 9, nxt)
            elif op == _OP_STATISTICS and length >= _STATISTICS_HEAD + 4:
                body = pos + 9 + _STATISTICS_HEAD
                size = _U32.unpack_from(buf, body)[0]
                if body + 4 + size <= nxt and size % _CHANNEL_COUNT.size == 0:
                    self.channel_counts = dict(
                        _CHANNEL_COUNT.iter_unpack(buf[body + 4 : body + 4 + size])
                    )
            pos = nxt

    def check_counts(self, salvage: Salvage | None = None, counted: int = 0) -> None:
        """At the end: the messages yielded per topic match the file's Statistics record.

        A Message Index that leaves out messages would otherwise lose them silently. With
        ``salvage`` (a damaged file), the shortfall is the count of messages lost, replacing
        the ``counted`` ones the skipped chunks' indexes gave.
        """
        expected = self.expected()
        if expected is not None:
            check_counts(self.path, expected, self.yielded, salvage, counted)

    def expected(self) -> dict[str, int] | None:
        """Messages per wanted topic in the Statistics record, or None without one."""
        if self.channel_counts is None:
            return None
        expected: dict[str, int] = {}
        for cid, count in self.channel_counts.items():
            topic = self.channel_topic.get(cid)
            if topic in self.topics:
                expected[topic] = expected.get(topic, 0) + count
        return expected

    def record(self, stats: ScanStats | None, counted: int) -> None:
        """Copy what the scan found into ``stats``."""
        if stats is not None:
            stats.yielded = dict(self.yielded)
            stats.expected = self.expected()
            stats.counted = counted
            stats.last_log_ns = self.last_log_ns

    def records(self, buf: memoryview, pos: int, end: int) -> None:
        """Walk the records of ``buf[pos:end]``; wanted messages go to ``collect``."""
        unpack_header = _HEADER.unpack_from
        unpack_full = _HEADER_MESSAGE.unpack_from
        wanted = self.wanted
        head = _MESSAGE_HEAD
        op_message = _OP_MESSAGE
        fast_end = end - 9 - head  # a message's header and fixed fields fit before ``end``
        while pos < end:
            if pos <= fast_end:  # one unpack for header and message fields (garbage if no message)
                op, length, cid, log_time = unpack_full(buf, pos)
            elif pos + 9 <= end:
                op, length = unpack_header(buf, pos)
                cid = log_time = 0
                if op == op_message:
                    raise self._error(f'MCAP message record too short at byte {pos}')
            else:
                raise self._error(f'truncated MCAP record header at byte {pos}')
            body = pos + 9
            nxt = body + length
            if nxt > end:
                raise self._error(f'truncated MCAP record (opcode {op:#04x}) at byte {pos}')
            if op == op_message:
                if length < head:
                    raise self._error(f'MCAP message record too short at byte {pos}')
                dest = wanted.get(cid)
                if dest is not None:
                    dest[0].append(log_time)
                    dest[1].append(body + head)
                    dest[2].append(length - head)
            elif op == _OP_CHANNEL:
                self.channel(buf, body, nxt)
                wanted = self.wanted
            pos = nxt

    def chunk(self, body: bytes, pos: int) -> memoryview:
        """The (decompressed) records of the body of the Chunk record at file offset ``pos``."""
        buf = memoryview(body)
        if len(buf) < 32:
            raise self._error(f'MCAP chunk record too short at byte {pos}')
        usize, crc, clen = _CHUNK.unpack_from(buf, 0)
        rpos = 32 + clen
        if rpos + 8 > len(buf):
            raise self._error(f'MCAP chunk record too short at byte {pos}')
        compression = bytes(buf[32:rpos]).decode()
        rlen = _U64.unpack_from(buf, rpos)[0]
        if rpos + 8 + rlen > len(buf):
            raise self._error(f'truncated MCAP chunk records at byte {pos}')
        data = buf[rpos + 8 : rpos + 8 + rlen]
        if compression:
            data = memoryview(_decompress(compression, data, usize))
        elif len(data) != usize:
            raise self._error(f'MCAP chunk at byte {pos}: {len(data)} bytes, expected {usize}')
        if crc and zlib.crc32(data) != crc:
            raise self._error(f'MCAP chunk at byte {pos}: CRC mismatch')
        return data

    def indexed(self, records: memoryview, indexes: dict[int, NDArray[np.void]]) -> bool:
        """Collect the wanted messages of a chunk through its indexes; False if unusable.

        Unusable: a channel unknown so far (defined inside this chunk), or an entry that does
        not point at a message record of its channel with its log time.
        """
        if any(cid not in self.channel_topic for cid in indexes):
            return False
        found: dict[str, list[tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]]]
        found = {}
        size = len(records)
        for cid, entries in indexes.items():
            topic = self.channel_topic[cid]
            if topic not in self.topics or entries.size == 0:
                continue
            offset = entries['offset'].astype(np.int64)
            log_time = entries['log_time'].astype(np.int64)
            if offset.min() < 0 or offset.max() + 9 + _MESSAGE_HEAD > size:
                return False
            length = _at(records, offset + 1, '<u8')
            ok = (
                (np.frombuffer(records, dtype=np.uint8)[offset] == _OP_MESSAGE)
                & (length >= _MESSAGE_HEAD)
                & (offset + 9 + length <= size)
                & (_at(records, offset + 9, '<u2') == cid)
                & (_at(records, offset + 15, '<u8') == log_time)
            )
            if not ok.all():
                return False
            found.setdefault(topic, []).append(
                (log_time, offset + 9 + _MESSAGE_HEAD, length - _MESSAGE_HEAD)
            )
        self.pending = [
            (
                topic,
                np.concatenate([p[0] for p in parts]),
                np.concatenate([p[1] for p in parts]),
                np.concatenate([p[2] for p in parts]),
            )
            for topic, parts in found.items()
        ]
        return True

    def flush(self, buffer: memoryview) -> Iterator[Batch]:
        """Yield the current batch per topic (sorted by log time if asked) and reset it."""
        batches = self.pending
        self.pending = []
        for topic, (times, starts, lengths) in self.collect.items():
            if times:
                batches.append(
                    (
                        topic,
                        np.array(times, dtype=np.int64),
                        np.array(starts, dtype=np.int64),
                        np.array(lengths, dtype=np.int64),
                    )
                )
                times.clear()
                starts.clear()
                lengths.clear()
        for topic, t, start, length in batches:
            # file order (walked batches are in it already), then stable by log time
            order = np.argsort(start, kind='stable')
            if self.sort_by_time:
                order = order[np.argsort(t[order], kind='stable')]
            if not bool((order[1:] > order[:-1]).all()):
                t, start, length = t[order], start[order], length[order]
            self.yielded[topic] = self.yielded.get(topic, 0) + t.size
            if t.size:
                self.last_log_ns = max(self.last_log_ns, int(t.max()))
            yield topic, t, Spans(buffer, start, length)


def check_counts(
    path: Path,
    expected: dict[str, int],
    yielded: dict[str, int],
    salvage: Salvage | None = None,
    counted: int = 0,
) -> None:
    """The messages yielded per topic match the file's Statistics record.

    A Message Index that leaves out messages would otherwise lose them silently. With
    ``salvage`` (a damaged file), the shortfall is the count of messages lost, replacing
    the ``counted`` ones the skipped chunks' indexes gave.
    """
    shortfall = 0
    for topic, count in expected.items():
        got = yielded.get(topic, 0)
        if got != count and not (salvage is not None and salvage.recovered):
            raise ValueError(
                f'{path}: {got} messages found on {topic}, but the file statistics count '
                f'{count} (damaged message index?)'
            )
        shortfall += max(count - got, 0)
    if salvage is not None and salvage.recovered:
        salvage.lost_total((salvage.lost_messages or 0) - counted + shortfall)


def scan_mcap(
    path: str | Path,
    topics: set[str],
    *,
    sort_by_time: bool = True,
    use_index: bool = True,
    stats: ScanStats | None = None,
    salvage: Salvage | None = None,
    span: tuple[int, int | None] | None = None,
    after_log_ns: int = 0,
) -> Iterator[Batch]:
    """Scan an MCAP file for the raw messages of some topics.

    Parameters
    ----------
    path : str or Path
        An ``.mcap`` file (for a rosbag2 bag directory, pass the ``.mcap`` file inside it).
    topics : set of str
        Topics to return; messages of other channels are skipped without copying.
    sort_by_time : bool, optional
        Stable-sort each batch's messages by log time (default). If false, file order.
    use_index : bool, optional
        Locate messages through the chunks' Message Index records where they are usable
        (default); if false, always walk the records (the reference the tests compare with).
    stats : ScanStats, optional
        Counts the chunks read each way.
    salvage : Salvage, optional
        Read a damaged file as far as it is intact (a file cut anywhere, without footer or
        summary; a damaged chunk is skipped) and record in ``salvage`` what was skipped.
        Without it, damage raises ``ValueError``.
    span : (int, int or None), optional
        Scan only the records from file offset ``span[0]`` (a record's start, e.g. a chunk's
        from :func:`chunk_offsets`) up to ``span[1]`` (another's; None: to the end). The
        channels come from the summary (which must have them), and the message counts are not
        checked against the Statistics record (``stats`` gets them: :func:`check_counts` over
        all the spans).
    after_log_ns : int, optional
        Newest log time of the spans before this one, ns (the start of a gap in ``salvage``).

    Yields
    ------
    topic : str
        A wanted topic with messages in this batch.
    log_times_ns : ndarray of int64, shape (N,)
        Log times of these messages in ns.
    spans : fog_temp_comp.bag.cdr.Spans
        Where the N messages' raw data (CDR for ROS 2, as ``AnyReader.messages()`` yields it)
        lie in the file's or the chunk's decompressed buffer; ``spans.payloads()`` gives them
        as memoryviews.

    Raises
    ------
    ValueError
        If the file is not MCAP, is truncated, or uses an unsupported compression (raised on
        the first ``next()``, as this is a generator).

    Notes
    -----
    A batch is one chunk, or the unchunked messages between chunks; batches come in file order
    and are not merged in time across chunks (see the module docstring).

    """
    path = Path(path)
    scanner = _Scanner(path, set(topics), sort_by_time)
    scanner.last_log_ns = after_log_ns
    with path.open('rb') as file:
        reader = _RecordReader(file, path, salvage)
        if use_index or span is not None:
            summary = reader.summary()
            if summary:
                scanner.summary_channels(summary)
            if span is not None and not scanner.channel_topic:
                raise ValueError(f'{path}: a span needs the channels of a summary section')
        loose = bytearray()  # unchunked Channel and Message records, walked in batches
        pos, stop = (len(MAGIC), None) if span is None else span
        while True:
            if stop is not None and pos >= stop:
                yield from _walk_loose(scanner, loose)
                scanner.record(stats, reader.counted)
                return
            try:
                op, length = reader.header(pos)
            except _DamagedError:
                yield from _walk_loose(scanner, loose)
                assert salvage is not None
                pos = yield from _past_damage(scanner, reader, pos)
                if pos < 0:  # the file ends here (cut)
                    _finish(scanner, reader, stats, salvage, whole=span is None)
                    return
                continue
            body_pos = pos + 9
            pos = body_pos + length
            if op in (_OP_CHUNK, _OP_FOOTER) or len(loose) > _LOOSE_BATCH:
                yield from _walk_loose(scanner, loose)
            if op == _OP_FOOTER:
                _finish(scanner, reader, stats, salvage, whole=span is None)
                return
            if op == _OP_CHUNK:
                pos = yield from _scan_chunk(
                    scanner, reader, body_pos, length, use_index, stats, salvage
                )
            elif op in (_OP_MESSAGE, _OP_CHANNEL):
                loose += reader.read(body_pos - 9, length + 9)
            # other records (header, schemas, attachments, metadata, indexes) are skipped


def _scan_chunk(
    scanner: _Scanner,
    reader: _RecordReader,
    body_pos: int,
    length: int,
    use_index: bool,
    stats: ScanStats | None,
    salvage: Salvage | None,
) -> Generator[Batch, None, int]:
    """The batches of the chunk whose body starts at ``body_pos``.

    Returns the next record's offset: past the chunk's Message Index records, or past a
    damaged chunk (with ``salvage``; without, the damage raises).
    """
    pos = body_pos + length
    body = reader.read(body_pos, length)
    try:
        records = scanner.chunk(body, body_pos - 9)
        indexes, pos = reader.message_indexes(pos)
        if use_index and indexes and scanner.indexed(records, indexes):
            if stats is not None:
                stats.indexed_chunks += 1
        else:
            scanner.records(records, 0, len(records))
            if stats is not None:
                stats.walked_chunks += 1
    except (ValueError, UnicodeDecodeError, zstd.ZstdError, RuntimeError) as err:
        if salvage is None:
            raise
        scanner.discard()
        channels = (set(scanner.wanted), set(scanner.channel_topic))
        return reader.skip_chunk(body_pos - 9, body, pos, err, channels)
    yield from scanner.flush(records)
    return pos


def _past_damage(
    scanner: _Scanner, reader: _RecordReader, pos: int
) -> Generator[Batch, None, int]:
    """The intact records of a chunk the file ends in, if any.

    Returns where the next intact chunk starts (-1: nothing follows).
    """
    cut = reader.cut_chunk(pos)
    if cut is not None:
        scanner.records(cut, 0, len(cut))
        yield from scanner.flush(cut)
    return reader.skip_to_next_chunk(pos, scanner.last_log_ns)


def _finish(
    scanner: _Scanner,
    reader: _RecordReader,
    stats: ScanStats | None,
    salvage: Salvage | None,
    *,
    whole: bool,
) -> None:
    """At the end of the scan: the counts into ``stats``.

    They are checked against the Statistics record when the whole file was scanned (a span's
    are checked over all the spans, by :func:`check_counts`).
    """
    scanner.record(stats, reader.counted)
    if whole:
        scanner.check_counts(salvage, reader.counted)


def chunk_offsets(path: str | Path) -> list[int]:
    """File offsets of the Chunk records an intact MCAP file's summary lists, in file order.

    Empty when the file is cut (no trailing magic), has no summary, or its summary has no
    Chunk Index records or no Channel records: then only a whole scan is safe.
    """
    path = Path(path)
    with path.open('rb') as file:
        try:
            reader = _RecordReader(file, path)
        except ValueError:
            return []
        summary = memoryview(reader.summary())
    offsets: list[int] = []
    channels = False
    pos = 0
    while pos + 9 <= len(summary):
        op, length = _HEADER.unpack_from(summary, pos)
        nxt = pos + 9 + length
        if nxt > len(summary):
            return []
        if op == _OP_CHUNK_INDEX and length >= 24:
            offsets.append(_U64.unpack_from(summary, pos + 9 + 16)[0])
        channels = channels or op == _OP_CHANNEL
        pos = nxt
    return sorted(offsets) if channels else []


_Channels = tuple[set[int], set[int]]  # wanted and known channel ids


class _DamagedError(Exception):
    """A record header that runs past the end of the file (or is not one)."""


#: unchunked records are walked once this many bytes have gathered
_LOOSE_BATCH = 8 << 20


def _walk_loose(scanner: _Scanner, loose: bytearray) -> Iterator[Batch]:
    """Walk the gathered unchunked records, yield their batches, and empty ``loose``."""
    if not loose:
        return
    buf = memoryview(bytes(loose))
    loose.clear()
    scanner.records(buf, 0, len(buf))
    yield from scanner.flush(buf)


class _RecordReader:
    """Reads an MCAP file record by record (one chunk in memory at a time, not the file).

    With a :class:`Salvage`, a file without trailing magic (cut) is read up to its end, and
    damaged records raise :class:`_DamagedError` for the caller to skip (:meth:`skip_chunk`,
    :meth:`skip_to_next_chunk`), which records the damage.
    """

    def __init__(self, file: BinaryIO, path: Path, salvage: Salvage | None = None) -> None:
        self.file = file
        self.path = path
        self.salvage = salvage
        size = file.seek(0, 2)
        file.seek(0)
        if file.read(len(MAGIC)) != MAGIC:
            raise ValueError(f'{path}: not an MCAP file (bad magic)')
        file.seek(max(size - len(MAGIC), 0))
        self.cut = size < 2 * len(MAGIC) or file.read(len(MAGIC)) != MAGIC
        if self.cut and salvage is None:
            raise ValueError(f'{path}: truncated MCAP file (no trailing magic)')
        self.end = size if self.cut else size - len(MAGIC)  # records lie in [len(MAGIC), end)
        self.read_to = 0  # file offset up to which :meth:`cut_chunk` read uncompressed records
        self.counted = 0  # messages lost in skipped chunks, counted from their indexes

    def read(self, pos: int, size: int) -> bytes:
        """``size`` bytes at ``pos`` (within the records)."""
        self.file.seek(pos)
        data = self.file.read(size)
        if len(data) != size:  # pragma: no cover - header() checks the bounds first
            raise ValueError(f'{self.path}: truncated MCAP record at byte {pos}')
        return data

    def header(self, pos: int) -> tuple[int, int]:
        """(opcode, body length) of the record at ``pos``; raises if it runs past the end."""
        if pos + 9 > self.end:
            if self.salvage is not None:
                raise _DamagedError
            raise ValueError(f'{self.path}: truncated MCAP file (no footer record)')
        op, length = _HEADER.unpack(self.read(pos, 9))
        if pos + 9 + length > self.end or (self.salvage is not None and not 0 < op < 0x20):
            if self.salvage is not None:
                raise _DamagedError
            raise ValueError(
                f'{self.path}: truncated MCAP record (opcode {op:#04x}) at byte {pos}'
            )
        return op, length

    def summary(self) -> bytes:
        """The summary section the footer points to, or b'' (none, or not understood)."""
        footer = self.end - 29
        if self.cut or footer < len(MAGIC):
            return b''
        op, length, start, _offsets, _crc = _FOOTER.unpack(self.read(footer, 29))
        if op != _OP_FOOTER or length != 20 or not len(MAGIC) <= start < footer:
            return b''
        return self.read(start, footer - start)

    def message_indexes(self, pos: int) -> tuple[dict[int, NDArray[np.void]], int]:
        """The Message Index records at ``pos`` (channel id -> entries) and the next offset.

        With a salvage, a malformed index ends the list (the chunk is then walked).
        """
        indexes: dict[int, NDArray[np.void]] = {}
        while pos + 9 <= self.end:
            op, length = _HEADER.unpack(self.read(pos, 9))
            if op != _OP_MESSAGE_INDEX:
                break
            if pos + 9 + length > self.end or length < _INDEX_HEAD.size:
                if self.salvage is not None:
                    return {}, pos
                raise ValueError(f'{self.path}: malformed MCAP message index at byte {pos}')
            body = self.read(pos + 9, length)
            cid, nbytes = _INDEX_HEAD.unpack_from(body, 0)
            if nbytes % 16 or _INDEX_HEAD.size + nbytes > length:
                if self.salvage is not None:
                    return {}, pos
                raise ValueError(f'{self.path}: malformed MCAP message index at byte {pos}')
            indexes[cid] = np.frombuffer(
                body, dtype=_INDEX_ENTRY, count=nbytes // 16, offset=_INDEX_HEAD.size
            )
            pos += 9 + length
        return indexes, pos

    def skip_chunk(
        self, chunk_pos: int, body: bytes, after: int, err: Exception, channels: _Channels
    ) -> int:
        """Record a damaged chunk as skipped; the offset after it and its message indexes.

        The messages lost are counted from its Message Index records (``channels``: the
        wanted and the known channel ids) when they are whole and name known channels only.
        """
        assert self.salvage is not None
        wanted, known = channels
        pos = chunk_pos + 9 + len(body)
        lost: int | None = 0
        while pos + 9 <= self.end:  # its Message Index records, if they look whole
            op, length = _HEADER.unpack(self.read(pos, 9))
            if op != _OP_MESSAGE_INDEX or pos + 9 + length > self.end:
                break
            if length >= _INDEX_HEAD.size and lost is not None:
                cid, nbytes = _INDEX_HEAD.unpack_from(self.read(pos + 9, _INDEX_HEAD.size), 0)
                if cid not in known or nbytes % 16:
                    lost = None
                elif cid in wanted:
                    lost += nbytes // 16
            pos += 9 + length
        if pos == chunk_pos + 9 + len(body):
            lost = None  # no index: how many is not known
        pos = max(pos, after)
        gap = struct.unpack_from('<QQ', body) if len(body) >= 16 else None
        self.salvage.damage(
            f'damaged chunk at byte {chunk_pos} ({err})',
            skipped_bytes=pos - chunk_pos,
            chunks=1,
            gap_ns=(int(gap[0]), int(gap[1])) if gap and gap[0] <= gap[1] else None,
            lost_messages=lost,
        )
        self.counted += lost or 0
        return pos

    def cut_chunk(self, pos: int) -> memoryview | None:
        """The whole records at the start of a Chunk record the file ends in, if it is one.

        Uncompressed records are read up to the cut; zstd and lz4 frames are decompressed as
        far as they go. None when ``pos`` is not a chunk that runs past the end of the file.
        """
        if not self.cut or pos + 9 + 40 > self.end:
            return None
        head = self.read(pos, 9 + 32)
        op, length = _HEADER.unpack_from(head, 0)
        clen = _U32.unpack_from(head, 9 + 28)[0]
        if op != _OP_CHUNK or pos + 9 + length <= self.end or clen > 8:
            return None
        start = pos + 9 + 32
        if start + clen + 8 > self.end:
            return None
        name = self.read(start, clen)
        data = self.read(start + clen + 8, self.end - start - clen - 8)
        try:
            if name == b'zstd':
                data = zstd.ZstdDecompressor().decompress(data)
            elif name == b'lz4' and _lz4_decompress is not None:
                from lz4.frame import LZ4FrameDecompressor

                data = LZ4FrameDecompressor().decompress(data)
            elif name != b'':
                return None
        except (zstd.ZstdError, RuntimeError, ValueError):
            return None
        whole = 0  # end of the last whole record
        while whole + 9 <= len(data):
            nxt = whole + 9 + _U64.unpack_from(data, whole + 1)[0]
            if nxt > len(data):
                break
            whole = nxt
        if name == b'':
            self.read_to = start + clen + 8 + whole
        return memoryview(data)[:whole]

    def skip_to_next_chunk(self, pos: int, last_log_ns: int) -> int:
        """Record unreadable bytes from ``pos`` on; the offset of the next whole chunk, or -1."""
        assert self.salvage is not None
        found = self._next_chunk(pos + 1) if pos + 9 <= self.end else None
        if found is None:
            size = self.end - max(pos, self.read_to)
            if self.cut:
                what = f'no footer or summary: the file ends at byte {self.end}'
                what += f' inside a record at byte {pos}' if size > 0 else ''
                self.salvage.damage(
                    what + ' (recorder killed?)',
                    skipped_bytes=max(size, 0),
                    gap_ns=(last_log_ns, None) if size > 0 else None,
                )
            else:
                self.salvage.damage(
                    f'unreadable records from byte {pos} to the end', skipped_bytes=max(size, 0)
                )
            return -1
        start_ns = struct.unpack('<Q', self.read(found + 9, 8))[0]
        self.salvage.damage(
            f'unreadable records at bytes {pos}-{found}',
            skipped_bytes=found - pos,
            gap_ns=(last_log_ns, int(start_ns)),
        )
        return found

    def _next_chunk(self, pos: int) -> int | None:
        """Offset of the next record from ``pos`` on that is a whole, consistent Chunk record."""
        block = 4 << 20
        while pos + 9 + 40 <= self.end:
            self.file.seek(pos)
            data = self.file.read(min(block + 64, self.end - pos))
            at = data.find(b'\x06')
            while 0 <= at < min(block, len(data)):
                if self._is_chunk(pos + at):
                    return pos + at
                at = data.find(b'\x06', at + 1)
            pos += block
        return None

    def _is_chunk(self, pos: int) -> bool:
        if pos + 9 + 40 > self.end:
            return False
        head = self.read(pos, 9 + 32)
        _op, length = _HEADER.unpack_from(head, 0)
        start, stop, _usize, _crc, clen = struct.unpack_from('<QQQII', head, 9)
        if start > stop or clen > 8 or pos + 9 + length > self.end or 40 + clen > length:
            return False
        tail = self.read(pos + 9 + 32, clen + 8)
        name = tail[:clen]
        rlen = _U64.unpack_from(tail, clen)[0]
        return name in (b'', b'zstd', b'lz4') and length == 40 + clen + rlen


def mcap_topics(path: str | Path) -> dict[str, str]:
    """``{topic: message type}`` of an MCAP file, read from its records (damage skipped).

    For files whose summary is missing: Schema and Channel records are collected from the
    data section, chunks decompressed only while their Message Index names a channel not
    seen yet (or has none).
    """
    path = Path(path)
    schemas: dict[int, str] = {}
    channels: dict[int, tuple[int, str]] = {}
    with path.open('rb') as file:
        reader = _RecordReader(file, path, Salvage(path))
        pos = len(MAGIC)
        while True:
            try:
                op, length = reader.header(pos)
            except _DamagedError:
                cut = reader.cut_chunk(pos)
                if cut is not None:
                    _definitions(cut, schemas, channels)
                pos = reader.skip_to_next_chunk(pos, 0)
                if pos < 0:
                    break
                continue
            body_pos, pos = pos + 9, pos + 9 + length
            if op == _OP_FOOTER:
                break
            if op in (_OP_SCHEMA, _OP_CHANNEL):
                _definitions(reader.read(body_pos - 9, length + 9), schemas, channels)
            elif op == _OP_CHUNK:
                indexes, after = reader.message_indexes(pos)
                if indexes and all(cid in channels for cid in indexes):
                    pos = after
                    continue
                scanner = _Scanner(path, set(), True)
                try:
                    records = scanner.chunk(reader.read(body_pos, length), body_pos - 9)
                except (ValueError, UnicodeDecodeError, zstd.ZstdError, RuntimeError):
                    continue
                _definitions(records, schemas, channels)
    return {topic: schemas.get(sid, '') for sid, topic in channels.values()}


def _definitions(
    buf: bytes | memoryview, schemas: dict[int, str], channels: dict[int, tuple[int, str]]
) -> None:
    """Collect the Schema (id -> name) and Channel (id -> schema id, topic) records of ``buf``."""
    pos = 0
    view = memoryview(buf)
    while pos + 9 <= len(view):
        op, length = _HEADER.unpack_from(view, pos)
        body, nxt = pos + 9, pos + 9 + length
        if nxt > len(view):
            return
        try:
            if op == _OP_SCHEMA and length >= 6:
                sid, size = struct.unpack_from('<HI', view, body)
                schemas[sid] = bytes(view[body + 6 : body + 6 + size]).decode()
            elif op == _OP_CHANNEL and length >= 8:
                cid, sid, size = _CHANNEL.unpack_from(view, body)
                channels[cid] = (sid, bytes(view[body + 8 : body + 8 + size]).decode())
        except (struct.error, UnicodeDecodeError):
            pass
        pos = nxt


def _benchmark(path: str, topics: set[str]) -> None:  # pragma: no cover
    """Time :func:`scan_mcap` against ``AnyReader.messages()`` on one file and print msgs/s."""
    import time

    from rosbags.highlevel import AnyReader

    def timed(fn: Callable[[], int]) -> tuple[int, float]:
        t0 = time.perf_counter()
        n = fn()
        return n, time.perf_counter() - t0

    def scan() -> int:
        return sum(t.size for _, t, _ in scan_mcap(path, topics))

    def rosbags() -> int:
        n = 0
        with AnyReader([Path(path)]) as reader:
            conns = [c for c in reader.connections if c.topic in topics]
            for _ in reader.messages(connections=conns):
                n += 1
        return n

    for name, fn in (('scan_mcap', scan), ('AnyReader', rosbags)):
        n, dt = timed(fn)
        print(f'{name:10s} {n:9d} msgs  {dt:7.3f} s  {n / dt:12.0f} msgs/s')


if __name__ == '__main__':  # pragma: no cover
    if len(sys.argv) < 3:
        sys.exit('usage: python -m fog_temp_comp.bag.mcapscan FILE.mcap TOPIC [TOPIC ...]')
    _benchmark(sys.argv[1], set(sys.argv[2:]))
