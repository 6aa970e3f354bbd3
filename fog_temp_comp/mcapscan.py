"""Fast raw scanner for MCAP files (rosbag2's default storage), without per-message objects.

``rosbags``' ``AnyReader.messages()`` parses every MCAP record in Python and builds a tuple per
message; for the vectorised CDR decoders in :mod:`fog_temp_comp.cdr` that is the bottleneck.
:func:`scan_mcap` yields, per chunk and topic, a log-time array and the messages' positions in
the (decompressed) chunk as :class:`fog_temp_comp.cdr.Spans`, which the decoders read in place:

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
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.cdr import Spans

if sys.version_info >= (3, 14):
    from compression import zstd
else:  # pragma: no cover
    from backports import zstd

try:
    from lz4.frame import decompress as _lz4_decompress
except ImportError:  # pragma: no cover
    _lz4_decompress = None

__all__ = ['MAGIC', 'ScanStats', 'Spans', 'scan_mcap']

MAGIC = b'\x89MCAP0\r\n'

_OP_FOOTER = 0x02
_OP_CHANNEL = 0x04
_OP_MESSAGE = 0x05
_OP_CHUNK = 0x06
_OP_MESSAGE_INDEX = 0x07

_HEADER = struct.Struct('<BQ')  # opcode, record length
_HEADER_MESSAGE = struct.Struct('<BQH4xQ')  # opcode, length, channel id, (sequence), log time
_MESSAGE_HEAD = 22  # channel id u16, sequence u32, log time u64, publish time u64
_CHANNEL = struct.Struct('<HHI')  # id, schema id, topic length
_CHUNK = struct.Struct('<16xQII')  # (start, end), uncompressed size, crc, compression length
_FOOTER = struct.Struct('<BQQQI')  # opcode, length, summary start, summary offset start, crc
_INDEX_HEAD = struct.Struct('<HI')  # channel id, byte length of the (log time, offset) array
_INDEX_ENTRY = np.dtype([('log_time', '<u8'), ('offset', '<u8')])
_U64 = struct.Struct('<Q')

Batch = tuple[str, NDArray[np.int64], Spans]


@dataclass
class ScanStats:
    """How :func:`scan_mcap` read the chunks of a file."""

    indexed_chunks: int = 0  # through their Message Index records
    walked_chunks: int = 0  # record by record


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

    def summary_channels(self, buf: memoryview, end: int) -> None:
        """Register the Channel records of the summary section, if the footer points to one."""
        footer = end - 29
        if footer < len(MAGIC):
            return
        op, length, summary, _offsets, _crc = _FOOTER.unpack_from(buf, footer)
        if op != _OP_FOOTER or length != 20 or not len(MAGIC) <= summary < footer:
            return
        pos = summary
        while pos + 9 <= footer:
            op, length = _HEADER.unpack_from(buf, pos)
            nxt = pos + 9 + length
            if nxt > footer:
                return
            if op == _OP_CHANNEL:
                self.channel(buf, pos + 9, nxt)
            pos = nxt

    def records(self, buf: memoryview, pos: int, end: int, top: bool) -> int:
        """Walk the records of ``buf[pos:end]``; return where a chunk or footer was found.

        Inside a chunk (``top`` false) walk to ``end``. Wanted messages go to ``collect``.
        """
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
            elif top and op in (_OP_CHUNK, _OP_FOOTER):
                return pos
            pos = nxt
        return end

    def chunk(self, buf: memoryview, pos: int) -> tuple[memoryview, int]:
        """Decode the Chunk record at ``pos``: its (decompressed) records and the next offset."""
        if pos + 9 > len(buf):
            raise self._error(f'truncated MCAP record header at byte {pos}')
        length = _U64.unpack_from(buf, pos + 1)[0]
        body = pos + 9
        nxt = body + length
        if body + 32 > nxt or nxt > len(buf):
            raise self._error(f'truncated MCAP chunk record at byte {pos}')
        usize, _crc, clen = _CHUNK.unpack_from(buf, body)
        cstart = body + 32
        rpos = cstart + clen
        if rpos + 8 > nxt:
            raise self._error(f'MCAP chunk record too short at byte {pos}')
        compression = bytes(buf[cstart:rpos]).decode()
        rlen = _U64.unpack_from(buf, rpos)[0]
        if rpos + 8 + rlen > nxt:
            raise self._error(f'truncated MCAP chunk records at byte {pos}')
        data = buf[rpos + 8 : rpos + 8 + rlen]
        if compression:
            data = memoryview(_decompress(compression, data, usize))
        return data, nxt

    def message_indexes(
        self, buf: memoryview, pos: int, end: int
    ) -> tuple[dict[int, NDArray[np.void]], int]:
        """The Message Index records at ``pos`` (channel id -> entries) and the next offset."""
        indexes: dict[int, NDArray[np.void]] = {}
        while pos + 9 + _INDEX_HEAD.size <= end and buf[pos] == _OP_MESSAGE_INDEX:
            length = _U64.unpack_from(buf, pos + 1)[0]
            body = pos + 9
            nxt = body + length
            cid, nbytes = _INDEX_HEAD.unpack_from(buf, body)
            if nxt > end or nbytes % 16 or body + _INDEX_HEAD.size + nbytes > nxt:
                raise self._error(f'malformed MCAP message index record at byte {pos}')
            indexes[cid] = np.frombuffer(
                buf, dtype=_INDEX_ENTRY, count=nbytes // 16, offset=body + _INDEX_HEAD.size
            )
            pos = nxt
        return indexes, pos

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
            yield topic, t, Spans(buffer, start, length)


def scan_mcap(
    path: str | Path,
    topics: set[str],
    *,
    sort_by_time: bool = True,
    use_index: bool = True,
    stats: ScanStats | None = None,
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

    Yields
    ------
    topic : str
        A wanted topic with messages in this batch.
    log_times_ns : ndarray of int64, shape (N,)
        Log times of these messages in ns.
    spans : fog_temp_comp.cdr.Spans
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
    data = path.read_bytes()
    if not data.startswith(MAGIC):
        raise ValueError(f'{path}: not an MCAP file (bad magic)')
    if len(data) < 2 * len(MAGIC) or not data.endswith(MAGIC):
        raise ValueError(f'{path}: truncated MCAP file (no trailing magic)')
    buf = memoryview(data)
    end = len(data) - len(MAGIC)
    scanner = _Scanner(path, set(topics), sort_by_time)
    if use_index:
        scanner.summary_channels(buf, end)
    pos = len(MAGIC)
    while True:
        pos = scanner.records(buf, pos, end, top=True)
        yield from scanner.flush(buf)
        if pos >= end:
            raise ValueError(f'{path}: truncated MCAP file (no footer record)')
        if buf[pos] == _OP_FOOTER:
            return
        records, pos = scanner.chunk(buf, pos)
        indexes, pos = scanner.message_indexes(buf, pos, end)
        if use_index and indexes and scanner.indexed(records, indexes):
            if stats is not None:
                stats.indexed_chunks += 1
        else:
            scanner.records(records, 0, len(records), top=False)
            if stats is not None:
                stats.walked_chunks += 1
        yield from scanner.flush(records)


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
        sys.exit('usage: python -m fog_temp_comp.mcapscan FILE.mcap TOPIC [TOPIC ...]')
    _benchmark(sys.argv[1], set(sys.argv[2:]))
