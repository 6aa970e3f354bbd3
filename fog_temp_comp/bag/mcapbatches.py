"""The state of one MCAP scan: channels, wanted messages gathered into per-topic batches, counts.

:class:`_Scanner` registers Channel records, decompresses chunks, collects the wanted
messages of a chunk through its Message Index (numpy, no Python per message) or by walking its
records, and yields them as batches (topic, log times ns, :class:`~fog_temp_comp.bag.cdr.Spans`).
:func:`check_counts` compares what was yielded with the file's Statistics record.
"""

from __future__ import annotations

import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.bag.cdr import Spans
from fog_temp_comp.bag.mcapformat import (
    _CHANNEL,
    _CHANNEL_COUNT,
    _CHUNK,
    _HEADER,
    _HEADER_MESSAGE,
    _MESSAGE_HEAD,
    _OP_CHANNEL,
    _OP_MESSAGE,
    _OP_STATISTICS,
    _STATISTICS_HEAD,
    _U32,
    _U64,
    _decompress,
)
from fog_temp_comp.bag.salvage import Salvage

__all__ = ['Batch', 'ScanStats', 'check_counts']

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
