"""Blocks of messages into rosbags' MCAP writer, assembled with numpy (no Python per message).

rosbags' ``rosbag2.Writer`` with MCAP storage builds every Message record in Python and closes a
chunk once it holds more than 1 MiB. :class:`McapBlockWriter` fills the same writer's chunks a
block at a time: the 31-byte record headers from one structured array, the payloads copied one
``memcpy`` per message through byte-stride views, the Message Index records from arrays. The
chunk boundaries, record layout, chunk and index records, compression, statistics and
``metadata.yaml`` are those of the per-message writer (rosbags writes the summary and the
metadata when it closes), so the file is byte for byte what ``Writer.write`` per message gives
(tested). Compressed chunks are compressed in a thread (zstd releases the GIL), so that the
compression overlaps with the caller's work on the next block; they are written in order.

It relies on the internals of the pinned rosbags version (``Writer.storage``, the MCAP storage's
pending chunk): :func:`supports` says whether they look as expected; if not, write per message.
"""

from __future__ import annotations

import struct
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from io import BytesIO
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.bag.cdr import Spans

__all__ = ['McapBlockWriter', 'chunk_compression', 'supports']

MAGIC = b'\x89MCAP0\r\n'
#: rosbags closes a chunk after the message that takes it over this many bytes
CHUNK_BYTES = 1 << 20
_OP_MESSAGE = 0x05
_OP_CHUNK = 0x06
_OP_MESSAGE_INDEX = 0x07
#: opcode, record length, channel id, sequence, log time, publish time
_MESSAGE_HEADER = np.dtype(
    [
        ('op', 'u1'),
        ('length', '<u8'),
        ('channel', '<u2'),
        ('sequence', '<u4'),
        ('log_time', '<u8'),
        ('publish_time', '<u8'),
    ]
)
_HEAD = _MESSAGE_HEADER.itemsize  # 31
#: compressed chunks waiting to be written at most
_IN_FLIGHT = 2
_INDEX_ENTRY = np.dtype([('log_time', '<u8'), ('offset', '<u8')])
_U64 = struct.Struct('<Q')


def supports(writer: Any) -> bool:
    """Whether ``writer`` (an open ``rosbags.rosbag2.Writer``) has the MCAP internals used here."""
    storage = getattr(writer, 'storage', None)
    chunk = getattr(storage, 'chunk', None)
    needed = ('bio', 'chunks', 'compressor', 'compression', 'channel_stats')
    return (
        type(storage).__name__ == 'McapWriter'
        and all(hasattr(storage, name) for name in needed)
        and all(hasattr(chunk, name) for name in ('bio', 'msgs', 'message_start_time'))
        and all(hasattr(writer, name) for name in ('counts', 'min_timestamp', 'max_timestamp'))
        and getattr(writer, 'compression_mode', None) is not None
        and writer.compression_mode.name in ('NONE', 'STORAGE')
    )


def chunk_compression(path: str | Path) -> str:
    """Compression of an MCAP file's first chunk (``''`` for none or no chunk), e.g. ``'zstd'``.

    To write an output compressed as its input was. Reads the records before the first chunk
    only; a file that is not MCAP or ends early gives ``''``.
    """
    with open(path, 'rb') as file:
        if file.read(8) != MAGIC:
            return ''
        for _ in range(64):
            head = file.read(9)
            if len(head) < 9:
                return ''
            op, length = struct.unpack('<BQ', head)
            if op == _OP_CHUNK:
                body = file.read(32)
                if len(body) < 32:
                    return ''
                size = struct.unpack_from('<I', body, 28)[0]
                return file.read(size).decode(errors='replace')
            file.seek(length, 1)
    return ''


def _string(text: str) -> bytes:
    data = text.encode()
    return struct.pack('<I', len(data)) + data


def _record(op: int, body: bytes) -> bytes:
    return bytes([op]) + _U64.pack(len(body)) + body


def _gather(
    out: NDArray[np.uint8],
    dst: NDArray[np.int64],
    src: NDArray[np.uint8],
    starts: NDArray[np.int64],
    lengths: NDArray[np.int64],
) -> None:
    """Copy ``src[starts[k]:][:lengths[k]]`` to ``out[dst[k]:]``, one ``memcpy`` per message."""
    unique = np.unique(lengths)
    for length in unique.tolist():
        if length == 0:
            continue
        idx = np.flatnonzero(lengths == length) if unique.size > 1 else slice(None)
        src_rows = np.lib.stride_tricks.as_strided(
            src, shape=(src.size - length + 1, length), strides=(1, 1), writeable=False
        )
        out_rows = np.lib.stride_tricks.as_strided(
            out, shape=(out.size - length + 1, length), strides=(1, 1)
        )
        out_rows[dst[idx]] = src_rows[starts[idx]]


class McapBlockWriter:
    """Write message blocks into an open rosbags MCAP ``Writer``; :meth:`finish` before close.

    Between the first :meth:`write` and :meth:`finish` this object owns the writer's pending
    chunk: do not call the writer's own ``write`` in between.
    """

    def __init__(self, writer: Any) -> None:
        if not supports(writer):
            raise ValueError('not a rosbags MCAP writer of the supported version')
        self._writer = writer
        self._storage = writer.storage
        chunk = self._storage.chunk
        if chunk.msgs:
            raise ValueError('the writer has messages in its pending chunk already')
        # schema and channel records rosbags put in the pending chunk
        self._parts: list[bytes] = [chunk.bio.getvalue()]
        self._size = len(self._parts[0])
        self._channels: list[NDArray[np.int64]] = []
        self._times: list[NDArray[np.int64]] = []
        self._offsets: list[NDArray[np.int64]] = []
        self._written = False
        # chunks are compressed in a thread (zstd releases the GIL) while the caller goes on;
        # they are written in order, at most _IN_FLIGHT waiting
        self._compress = self._storage.compressor
        self._pool = ThreadPoolExecutor(1) if self._storage.compression else None
        self._queue: deque[tuple[Any, ...]] = deque()

    def write(
        self, channel_ids: NDArray[np.int64], log_times_ns: NDArray[np.int64], spans: Spans
    ) -> None:
        """Append messages in order: channel (rosbags connection id), log time (ns), data."""
        cids = np.asarray(channel_ids, dtype=np.int64)
        times = np.asarray(log_times_ns, dtype=np.int64)
        starts = np.asarray(spans.starts, dtype=np.int64)
        lengths = np.asarray(spans.lengths, dtype=np.int64)
        if not cids.shape == times.shape == starts.shape == lengths.shape:
            raise ValueError('channel_ids, log_times_ns and spans must have one length')
        if cids.size == 0:
            return
        self._written = True
        self._count(cids, times)
        src = np.frombuffer(spans.buffer, dtype=np.uint8)
        sizes = _HEAD + lengths
        begin = 0
        while begin < cids.size:
            ends = self._size + np.cumsum(sizes[begin:])
            over = int(np.searchsorted(ends, CHUNK_BYTES, side='right'))
            stop = begin + min(over + 1, ends.size)  # the message crossing the limit is in
            part = slice(begin, stop)
            self._append(cids[part], times[part], src, starts[part], lengths[part])
            if over < ends.size:
                self._close_chunk()
            begin = stop

    def _count(self, cids: NDArray[np.int64], times: NDArray[np.int64]) -> None:
        """Statistics and metadata.yaml counts, as ``Writer.write`` keeps them."""
        writer, storage = self._writer, self._storage
        low, high = int(times.min()), int(times.max())
        writer.min_timestamp = min(low, writer.min_timestamp)
        writer.max_timestamp = max(high, writer.max_timestamp)
        storage.message_start_time = min(low, storage.message_start_time)
        storage.message_end_time = max(high, storage.message_end_time)
        unique, counts = np.unique(cids, return_counts=True)
        for cid, count in zip(unique.tolist(), counts.tolist(), strict=True):
            writer.counts[cid] += count
            storage.channel_stats[cid] += count

    def _append(
        self,
        cids: NDArray[np.int64],
        times: NDArray[np.int64],
        src: NDArray[np.uint8],
        starts: NDArray[np.int64],
        lengths: NDArray[np.int64],
    ) -> None:
        """Message records of these messages at the end of the pending chunk."""
        sizes = _HEAD + lengths
        at = np.cumsum(sizes) - sizes
        out = np.empty(int(sizes.sum()), dtype=np.uint8)
        head = np.zeros(cids.size, dtype=_MESSAGE_HEADER)
        head['op'] = _OP_MESSAGE
        head['length'] = lengths + (_HEAD - 9)
        head['channel'] = cids
        head['log_time'] = times
        head['publish_time'] = times
        _gather(
            out, at, head.view(np.uint8), np.arange(cids.size) * _HEAD, np.full(cids.size, _HEAD)
        )
        _gather(out, at + _HEAD, src, starts, lengths)
        self._channels.append(cids)
        self._times.append(times)
        self._offsets.append(at + self._size)
        self._parts.append(out.tobytes())
        self._size += out.size

    def _close_chunk(self) -> None:
        """Hand the pending chunk to the compressor thread; write the chunks done by then."""
        cids = np.concatenate(self._channels)
        times = np.concatenate(self._times)
        offsets = np.concatenate(self._offsets)
        data = b''.join(self._parts)
        self._parts, self._size = [], 0
        self._channels, self._times, self._offsets = [], [], []
        if self._pool is None:  # no compression: nothing to overlap
            self._write_chunk(cids, times, offsets, data, data)
            return
        self._queue.append((cids, times, offsets, data, self._pool.submit(self._compress, data)))
        while self._queue and (len(self._queue) > _IN_FLIGHT or self._queue[0][-1].done()):
            cids, times, offsets, data, future = self._queue.popleft()
            self._write_chunk(cids, times, offsets, data, future.result())

    def _write_chunk(
        self,
        cids: NDArray[np.int64],
        times: NDArray[np.int64],
        offsets: NDArray[np.int64],
        data: bytes,
        compressed: bytes,
    ) -> None:
        """Write a chunk record, its Message Index records, and keep its Chunk Index."""
        storage = self._storage
        start, end = int(times.min()), int(times.max())
        body = b''.join(
            [
                struct.pack('<QQQI', start, end, len(data), 0),
                _string(storage.compression),
                _U64.pack(len(compressed)),
            ]
        )
        bio = storage.bio
        chunk_start = bio.tell()
        bio.write(bytes([_OP_CHUNK]) + _U64.pack(len(body) + len(compressed)))
        bio.write(body)
        bio.write(compressed)
        chunk_end = bio.tell()
        # channels in order of first appearance, as the writer's dict of lists has them
        unique, first = np.unique(cids, return_index=True)
        index_offsets = []
        for cid in unique[np.argsort(first)].tolist():
            mine = cids == cid
            entries = np.empty(int(mine.sum()), dtype=_INDEX_ENTRY)
            entries['log_time'] = times[mine]
            entries['offset'] = offsets[mine]
            index_offsets.append((cid, bio.tell()))
            bio.write(
                _record(
                    _OP_MESSAGE_INDEX, struct.pack('<HI', cid, entries.nbytes) + entries.tobytes()
                )
            )
        info = BytesIO()
        info.write(
            struct.pack(
                '<QQQQI', start, end, chunk_start, chunk_end - chunk_start, len(index_offsets) * 10
            )
        )
        for cid, offset in index_offsets:
            info.write(struct.pack('<HQ', cid, offset))
        info.write(_U64.pack(bio.tell() - chunk_end))
        info.write(_string(storage.compression))
        info.write(struct.pack('<QQ', len(compressed), len(data)))
        storage.chunks.append(info)

    def finish(self) -> None:
        """Close the last, partly filled chunk and write every chunk (as ``close`` would)."""
        try:
            if self._channels:
                self._close_chunk()
            while self._queue:
                cids, times, offsets, data, future = self._queue.popleft()
                self._write_chunk(cids, times, offsets, data, future.result())
        finally:
            if self._pool is not None:
                self._pool.shutdown(wait=True, cancel_futures=True)
                self._pool = None
        if self._written:
            self._storage.chunk.bio = BytesIO()
