"""What an MCAP file holds, without scanning its messages: its topics and its chunks' offsets.

:func:`chunk_offsets` reads an intact file's summary (where a file can be split for reading
in two processes); :func:`mcap_topics` reads the Schema and Channel records of a file whose
summary is missing or damaged.
"""

from __future__ import annotations

import struct
from pathlib import Path

from fog_temp_comp.bag.mcapbatches import _Scanner
from fog_temp_comp.bag.mcapformat import (
    _CHANNEL,
    _CHUNK_ERRORS,
    _HEADER,
    _OP_CHANNEL,
    _OP_CHUNK,
    _OP_CHUNK_INDEX,
    _OP_FOOTER,
    _OP_SCHEMA,
    _U64,
    MAGIC,
)
from fog_temp_comp.bag.mcapreader import _DamagedError, _RecordReader
from fog_temp_comp.bag.salvage import Salvage

__all__ = ['chunk_offsets', 'mcap_topics']


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
                except _CHUNK_ERRORS:
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
