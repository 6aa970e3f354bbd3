"""Blocks of messages into rosbags' ROS 1 writer: the records of a block assembled with numpy.

rosbags' ``rosbag1.Writer.write`` builds each message data record from Python (a ``Header``
dict, three ``struct.pack``, three writes). Every such record is the same 42-byte header
(``op=2``, ``conn=<uint32>``, ``time=<uint32 sec><uint32 nsec>``), the payload length and the
payload. :func:`write_block` assembles the records of many messages in one buffer, writes it
into the writer's open chunk, keeps the chunk's per-connection index and time range as
``write`` does, and closes the chunk (rosbags' own ``write_chunk``) after the message that
takes it past the writer's threshold, as ``write`` does: the file is that of the per-message
writer, byte for byte (tested). It relies on the internals of the pinned rosbags version:
:func:`supports` says whether they look as expected; if not, write per message.
"""

from __future__ import annotations

import struct
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.bag.cdr import Spans
from fog_temp_comp.bag.mcapwrite import _gather

__all__ = ['supports', 'write_block']

_OP_MSGDATA = 2
# the header record of a message: its length, then op, conn and time fields with theirs
_HEADER = (
    struct.pack('<I', 38)
    + struct.pack('<I', 4)
    + b'op='
    + bytes([_OP_MSGDATA])
    + struct.pack('<I', 9)
    + b'conn='
    + b'\0\0\0\0'
    + struct.pack('<I', 13)
    + b'time='
    + b'\0' * 8
)
_CONN_AT = 4 + 8 + 4 + 5  # byte offset of the connection id in a record
_TIME_AT = _CONN_AT + 4 + 4 + 5
_LEN_AT = len(_HEADER)  # then the payload length (uint32) and the payload
_FIXED = _LEN_AT + 4


def supports(writer: Any) -> bool:
    """Whether ``writer`` (an open ``rosbags.rosbag1.Writer``) has the internals used here."""
    chunks = getattr(writer, 'chunks', None)
    return (
        type(writer).__name__ == 'Writer'
        and type(writer).__module__.startswith('rosbags.rosbag1')
        and isinstance(chunks, list)
        and bool(chunks)
        and all(hasattr(chunks[-1], n) for n in ('data', 'connections', 'start', 'end', 'pos'))
        and isinstance(getattr(writer, 'chunk_threshold', None), int)
        and callable(getattr(writer, 'write_chunk', None))
        and getattr(writer, 'bio', None) is not None
    )


def write_block(
    writer: Any,
    connection_ids: NDArray[np.int64],
    log_times_ns: NDArray[np.int64],
    spans: Spans,
) -> None:
    """Write N messages in order, as N calls of ``writer.write`` would.

    ``connection_ids`` are the ids of connections registered with the writer.
    """
    cids = np.asarray(connection_ids, dtype=np.int64)
    times = np.asarray(log_times_ns, dtype=np.int64)
    lengths = np.asarray(spans.lengths, dtype=np.int64)
    starts = np.asarray(spans.starts, dtype=np.int64)
    if times.size and (int(times.min()) < 0 or int(times.max()) // 10**9 >= 2**32):
        raise ValueError('log times must fit a ROS 1 time (uint32 seconds)')
    src = np.frombuffer(spans.buffer, dtype=np.uint8)
    sizes = _FIXED + lengths
    threshold = writer.chunk_threshold
    pos = 0
    while pos < times.size:
        chunk = writer.chunks[-1]
        offset = chunk.data.tell()
        ends = offset + np.cumsum(sizes[pos:])
        over = np.flatnonzero(ends > threshold)
        stop = pos + (int(over[0]) + 1 if over.size else times.size - pos)
        part = slice(pos, stop)
        record_at = ends[: stop - pos] - sizes[part]
        chunk.data.write(_records(cids[part], times[part], src, starts[part], lengths[part]))
        _index(chunk, cids[part], times[part], record_at)
        if over.size:
            writer.write_chunk(chunk)
        pos = stop


def _records(
    cids: NDArray[np.int64],
    times: NDArray[np.int64],
    src: NDArray[np.uint8],
    starts: NDArray[np.int64],
    lengths: NDArray[np.int64],
) -> bytes:
    """The message data records of one chunk's part, back to back."""
    sizes = _FIXED + lengths
    at = np.cumsum(sizes) - sizes
    out = np.zeros(int(sizes.sum()), dtype=np.uint8)
    rows = np.lib.stride_tricks.as_strided(
        out, shape=(max(out.size - _FIXED + 1, 0), _FIXED), strides=(1, 1)
    )
    fixed = np.empty((times.size, _FIXED), dtype=np.uint8)
    fixed[:, :_LEN_AT] = np.frombuffer(_HEADER, dtype=np.uint8)
    words = np.empty((times.size, 4), dtype='<u4')
    words[:, 0] = cids
    words[:, 1] = times // 10**9
    words[:, 2] = times % 10**9
    words[:, 3] = lengths
    as_bytes = words.view(np.uint8)
    fixed[:, _CONN_AT : _CONN_AT + 4] = as_bytes[:, 0:4]
    fixed[:, _TIME_AT : _TIME_AT + 8] = as_bytes[:, 4:12]
    fixed[:, _LEN_AT:_FIXED] = as_bytes[:, 12:16]
    rows[at] = fixed
    _gather(out, at + _FIXED, src, starts, lengths)
    return out.tobytes()


def _index(
    chunk: Any, cids: NDArray[np.int64], times: NDArray[np.int64], record_at: NDArray[np.int64]
) -> None:
    """The chunk's index entries (per connection, in first-seen order) and time range."""
    unique, first = np.unique(cids, return_index=True)
    for cid in unique[np.argsort(first)].tolist():
        mine = cids == cid
        chunk.connections[cid].extend(
            zip(times[mine].tolist(), record_at[mine].tolist(), strict=True)
        )
    chunk.start = min(int(times.min()), chunk.start)
    chunk.end = max(int(times.max()), chunk.end)
