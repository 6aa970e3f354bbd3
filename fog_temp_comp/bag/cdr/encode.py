"""Arrays to serialized Imu and Temperature messages, bit-identical to rosbags' serializers."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.bag.cdr.batches import (
    FloatArray,
    HeaderBatch,
    ImuBatch,
    TemperatureBatch,
    _split,
)


def _encode(
    batch: HeaderBatch, floats: FloatArray, *, ros1: bool, little_endian: bool, header_seq: bool
) -> list[bytes]:
    n = len(batch)
    n_floats = floats.shape[1]
    order = '<' if little_endian or ros1 else '>'
    words = np.ascontiguousarray(floats).view(np.uint64)
    seq = getattr(batch, 'seq', None)
    out: list[bytes] = []
    groups: list[tuple[NDArray[np.intp] | None, bytes]] = []
    for code, frame_id in enumerate(batch.frame_id_table):
        text = frame_id.encode('utf-8')
        if len(batch.frame_id_table) == 1:
            idx: NDArray[np.intp] | None = None
        else:
            idx = np.flatnonzero(batch.frame_id_index == code)
            if idx.size == 0:
                continue
        groups.append((idx, text))
    for idx, text in groups:
        m = n if idx is None else idx.size
        sel: Any = slice(None) if idx is None else idx
        if ros1:
            head = 16 if header_seq else 12
            float_offset = head + len(text)
            length_field = len(text)
            stamp = head - 12
        else:
            head = 16
            float_offset = 4 + ((12 + len(text) + 1 + 7) & ~7)
            length_field = len(text) + 1
            stamp = 4
        size = float_offset + 8 * n_floats
        names = ['sec', 'nanosec', 'length', 'floats']
        formats: list[Any] = [
            order + 'i4',
            order + 'u4',
            order + 'u4',
            (order + 'u8', (n_floats,)),
        ]
        offsets = [stamp, stamp + 4, stamp + 8, float_offset]
        if text:
            names.append('text')
            formats.append(('u1', (len(text),)))
            offsets.append(head)
        if ros1 and header_seq:
            names.append('seq')
            formats.append('<u4')
            offsets.append(0)
        if not ros1:
            names.append('encapsulation')
            formats.append('u1')
            offsets.append(1)
        dtype = np.dtype(
            {'names': names, 'formats': formats, 'offsets': offsets, 'itemsize': size}
        )
        records = np.zeros(m, dtype=dtype)
        records['sec'] = batch.stamp_sec[sel]
        records['nanosec'] = batch.stamp_nanosec[sel]
        records['length'] = length_field
        records['floats'] = words[sel]
        if text:
            records['text'] = np.frombuffer(text, dtype=np.uint8)
        if ros1 and header_seq and seq is not None:
            records['seq'] = seq[sel]
        if not ros1:
            records['encapsulation'] = 1 if little_endian else 0
        starts = np.arange(m, dtype=np.int64) * size
        pieces = _split(records.tobytes(), starts, np.full(m, size, dtype=np.int64))
        if idx is None:
            out = pieces
        else:
            if not out:
                out = [b''] * n
            for i, piece in zip(idx.tolist(), pieces, strict=True):
                out[i] = piece
    return out


def encode_imu_cdr(batch: ImuBatch, *, little_endian: bool = True) -> list[bytes]:
    """Serialize an :class:`ImuBatch` to CDR, bit-identical to rosbags' ``serialize_cdr``.

    Parameters
    ----------
    batch : ImuBatch
        N messages.
    little_endian : bool
        Byte order (encapsulation ``0001`` or ``0000``).

    Returns
    -------
    list of bytes, length N
        One serialized message each, with the encapsulation header.

    """
    return _encode(
        batch, batch.float_block(), ros1=False, little_endian=little_endian, header_seq=False
    )


def encode_temperature_cdr(batch: TemperatureBatch, *, little_endian: bool = True) -> list[bytes]:
    """Serialize a :class:`TemperatureBatch` to CDR; see :func:`encode_imu_cdr`.

    Parameters
    ----------
    batch : TemperatureBatch
        N messages.
    little_endian : bool
        Byte order.

    Returns
    -------
    list of bytes, length N
        One serialized message each.

    """
    return _encode(
        batch, batch.float_block(), ros1=False, little_endian=little_endian, header_seq=False
    )


def encode_imu_ros1(batch: ImuBatch, *, header_seq: bool = False) -> list[bytes]:
    """Serialize an :class:`ImuBatch` in ROS 1 format, bit-identical to rosbags.

    Parameters
    ----------
    batch : ImuBatch
        N messages.
    header_seq : bool
        Write ``Header.seq`` (``batch.seq``, or 0 without it), as a ROS 1 type store does.
        False (default) matches rosbags' ``serialize_ros1`` of ROS 2 types, which is what
        :class:`fog_temp_comp.bag.bagio.BagWriter` writes to ROS 1 bags.

    Returns
    -------
    list of bytes, length N
        One serialized message each.

    """
    return _encode(
        batch, batch.float_block(), ros1=True, little_endian=True, header_seq=header_seq
    )


def encode_temperature_ros1(batch: TemperatureBatch, *, header_seq: bool = False) -> list[bytes]:
    """Serialize a :class:`TemperatureBatch` in ROS 1 format; see :func:`encode_imu_ros1`.

    Parameters
    ----------
    batch : TemperatureBatch
        N messages.
    header_seq : bool
        Write ``Header.seq``.

    Returns
    -------
    list of bytes, length N
        One serialized message each.

    """
    return _encode(
        batch, batch.float_block(), ros1=True, little_endian=True, header_seq=header_seq
    )
