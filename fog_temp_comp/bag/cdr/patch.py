"""Corrected angular velocities written into copies of serialized Imu messages.

Every byte other than ``angular_velocity`` is kept, so the result equals serializing the
modified message (for messages rosbags serialized).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np
from numpy.typing import ArrayLike

from fog_temp_comp.bag.cdr.batches import (
    IMU_ANGULAR_VELOCITY,
    IMU_FLOATS,
    IMU_NAME,
    FloatArray,
    RawMessage,
    _split,
)
from fog_temp_comp.bag.cdr.parse import Spans, _as_list, _cdr_blocks, _Parsed, _ros1_blocks


def _patch_blocks(n: int, blocks: Iterator[_Parsed], new_rates: ArrayLike) -> list[bytes]:
    rates = np.asarray(new_rates, dtype=np.float64)
    if rates.shape != (n, 3):
        raise ValueError(f'new_rates has shape {rates.shape}, expected {(n, 3)}')
    out: list[bytes] = []
    for parsed in blocks:
        out += _patch_rates(parsed, rates[parsed.base : parsed.base + parsed.lengths.size])
    return out


def _patch_rates(parsed: _Parsed, rates: FloatArray) -> list[bytes]:
    out = bytearray(parsed.data)
    _write_rates(out, parsed, rates)
    return _split(bytes(out), parsed.starts, parsed.lengths)


def _write_rates(out: bytearray, parsed: _Parsed, rates: FloatArray) -> None:
    """Write ``rates`` (N, 3) over the angular velocities of ``parsed``'s messages in ``out``."""
    n = parsed.lengths.size
    buf = np.frombuffer(out, dtype=np.uint8)
    words = np.ascontiguousarray(rates).view(np.uint64)
    little = words.astype('<u8').view(np.uint8).reshape(n, 24)
    if parsed.little.all():
        values = little
    else:
        big = words.astype('>u8').view(np.uint8).reshape(n, 24)
        values = np.where(parsed.little[:, None], little, big)
    pos = parsed.starts + parsed.float_offset + 8 * IMU_ANGULAR_VELOCITY
    buf[pos[:, None] + np.arange(24)] = values


def patch_imu_angular_velocity_cdr(
    raws: Sequence[RawMessage], new_rates: ArrayLike
) -> list[bytes]:
    """Copies of CDR ``sensor_msgs/Imu`` messages with only ``angular_velocity`` replaced.

    Every other byte (header, padding, other fields, byte order) is kept, so for messages that
    rosbags serialized the result is bit-identical to serializing the modified message.

    Parameters
    ----------
    raws : sequence of bytes-like, length N
        Serialized messages (validated as in :func:`decode_imu_cdr`).
    new_rates : array_like, shape (N, 3)
        New angular velocity x, y, z (rad/s), written bit for bit.

    Returns
    -------
    list of bytes, length N
        The patched messages.

    """
    raws = _as_list(raws)
    return _patch_blocks(len(raws), _cdr_blocks(raws, IMU_FLOATS, IMU_NAME), new_rates)


def patch_imu_angular_velocity_spans(spans: Spans, new_rates: ArrayLike) -> bytearray:
    """A copy of ``spans.buffer`` with the CDR ``sensor_msgs/Imu`` at ``spans`` patched.

    As :func:`patch_imu_angular_velocity_cdr`, for messages lying in one buffer (e.g. an MCAP
    chunk): message k of the result is ``out[spans.starts[k]:][:spans.lengths[k]]``; every byte
    outside the messages' angular velocities is the input's.

    Parameters
    ----------
    spans : Spans, length N
        Serialized messages (validated as in :func:`decode_imu_cdr`).
    new_rates : array_like, shape (N, 3)
        New angular velocity x, y, z (rad/s), written bit for bit.

    Returns
    -------
    bytearray
        The patched copy of the buffer.

    """
    rates = np.asarray(new_rates, dtype=np.float64)
    if rates.shape != (len(spans), 3):
        raise ValueError(f'new_rates has shape {rates.shape}, expected {(len(spans), 3)}')
    out = bytearray(spans.buffer)
    for parsed in _cdr_blocks(spans, IMU_FLOATS, IMU_NAME):
        _write_rates(out, parsed, rates[parsed.base : parsed.base + parsed.lengths.size])
    return out


def patch_imu_angular_velocity_ros1(
    raws: Sequence[RawMessage], new_rates: ArrayLike, *, header_seq: bool | None = None
) -> list[bytes]:
    """ROS 1 variant of :func:`patch_imu_angular_velocity_cdr` (``header_seq`` as to decode).

    Parameters
    ----------
    raws : sequence of bytes-like, length N
        ROS 1 serialized messages.
    new_rates : array_like, shape (N, 3)
        New angular velocity (rad/s).
    header_seq : bool, optional
        Whether the Header has ``seq``; None infers it.

    Returns
    -------
    list of bytes, length N
        The patched messages.

    """
    raws = _as_list(raws)
    blocks = _ros1_blocks(raws, IMU_FLOATS, IMU_NAME, header_seq)
    return _patch_blocks(len(raws), blocks, new_rates)
