"""Reading an MCAP file record by record, one chunk in memory at a time, and skipping damage.

:class:`_RecordReader` reads record headers, the summary section and Message Index records
at file offsets (bytes); with a :class:`~fog_temp_comp.bag.salvage.Salvage` it reads a cut
file up to its end and skips damaged chunks and unreadable bytes, recording what it skipped.
"""

from __future__ import annotations

import struct
from pathlib import Path
from typing import BinaryIO

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.bag.mcapformat import (
    _FOOTER,
    _HEADER,
    _INDEX_ENTRY,
    _INDEX_HEAD,
    _OP_CHUNK,
    _OP_FOOTER,
    _OP_MESSAGE_INDEX,
    _U32,
    _U64,
    MAGIC,
    _decompress_cut,
)
from fog_temp_comp.bag.salvage import Salvage

_Channels = tuple[set[int], set[int]]  # wanted and known channel ids


class _DamagedError(Exception):
    """A record header that runs past the end of the file (or is not one)."""


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
        data = _decompress_cut(name, self.read(start + clen + 8, self.end - start - clen - 8))
        if data is None:
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
