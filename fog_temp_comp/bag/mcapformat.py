"""MCAP record layout: magic, opcodes, the ``struct`` formats of the records read, decompression.

Only what :mod:`fog_temp_comp.bag.mcapscan` and its helpers read is here (see the MCAP
specification, https://mcap.dev/spec). Offsets and lengths are bytes; times are ns.
"""

from __future__ import annotations

import struct
import sys

import numpy as np

if sys.version_info >= (3, 14):
    from compression import zstd
else:  # pragma: no cover
    from backports import zstd

try:
    from lz4.frame import decompress as _lz4_decompress
except ImportError:  # pragma: no cover
    _lz4_decompress = None

__all__ = ['MAGIC']

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

#: what decompressing and reading a damaged chunk can raise
_CHUNK_ERRORS = (ValueError, UnicodeDecodeError, zstd.ZstdError, RuntimeError)


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


def _decompress_cut(name: bytes, data: bytes) -> bytes | None:
    """As much of a cut chunk's ``data`` as its zstd or lz4 frames give (uncompressed: as is).

    None when the compression is not supported or the data does not decompress.
    """
    try:
        if name == b'zstd':
            return zstd.ZstdDecompressor().decompress(data)
        if name == b'lz4' and _lz4_decompress is not None:
            from lz4.frame import LZ4FrameDecompressor

            return LZ4FrameDecompressor().decompress(data)
    except (zstd.ZstdError, RuntimeError, ValueError):
        return None
    return data if name == b'' else None
