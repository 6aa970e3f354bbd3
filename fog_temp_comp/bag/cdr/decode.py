"""The public decoders: batches of serialized Imu, Temperature and bare numbers to arrays."""

from __future__ import annotations

import re
from collections.abc import Sequence

import numpy as np

from fog_temp_comp.bag.cdr.batches import (
    IMU_FLOATS,
    IMU_NAME,
    TEMPERATURE_FLOATS,
    TEMPERATURE_NAME,
    FloatArray,
    ImuBatch,
    ImuRateBatch,
    RawMessage,
    TemperatureBatch,
)
from fog_temp_comp.bag.cdr.parse import (
    Spans,
    _as_batch,
    _cdr_blocks,
    _imu_blocks,
    _imu_rate_blocks,
    _ros1_blocks,
    _temperature_blocks,
)


def decode_imu_cdr(raws: Sequence[RawMessage] | Spans) -> ImuBatch:
    """Decode CDR-serialized ``sensor_msgs/Imu`` messages (ROS 2: MCAP, sqlite3 bags).

    Parameters
    ----------
    raws : sequence of bytes-like, or Spans, length N
        Serialized messages with their 4-byte encapsulation header; little and big endian may
        be mixed.

    Returns
    -------
    ImuBatch
        N messages, in input order.

    Raises
    ------
    ValueError
        A message is too short, truncated, has trailing bytes beyond the 3 of padding allowed,
        an unsupported encapsulation, an unterminated or non-UTF-8 frame_id; the message's
        index is in the text.

    """
    raws = _as_batch(raws)
    return _imu_blocks(len(raws), _cdr_blocks(raws, IMU_FLOATS, IMU_NAME))


def decode_imu_rates_cdr(raws: Sequence[RawMessage] | Spans) -> ImuRateBatch:
    """:func:`decode_imu_cdr` for the header and angular velocity only (validated alike).

    Copies about half the bytes per message that the full decode does: what reading a bag for
    calibration needs.

    Parameters
    ----------
    raws : sequence of bytes-like, or Spans, length N
        Serialized messages with their encapsulation header.

    Returns
    -------
    ImuRateBatch
        N messages, in input order.

    """
    raws = _as_batch(raws)
    return _imu_rate_blocks(len(raws), _cdr_blocks(raws, IMU_FLOATS, IMU_NAME))


def decode_imu_rates_ros1(
    raws: Sequence[RawMessage] | Spans, *, header_seq: bool | None = None
) -> ImuRateBatch:
    """:func:`decode_imu_ros1` for the header and angular velocity only.

    Parameters
    ----------
    raws : sequence of bytes-like, or Spans, length N
        ROS 1 serialized messages.
    header_seq : bool, optional
        Whether the Header has ``uint32 seq``; None infers it.

    Returns
    -------
    ImuRateBatch
        N messages, in input order.

    """
    raws = _as_batch(raws)
    return _imu_rate_blocks(len(raws), _ros1_blocks(raws, IMU_FLOATS, IMU_NAME, header_seq))


def decode_temperature_cdr(raws: Sequence[RawMessage] | Spans) -> TemperatureBatch:
    """Decode CDR-serialized ``sensor_msgs/Temperature`` messages; see :func:`decode_imu_cdr`.

    Parameters
    ----------
    raws : sequence of bytes-like, or Spans, length N
        Serialized messages with their encapsulation header.

    Returns
    -------
    TemperatureBatch
        N messages, in input order.

    """
    raws = _as_batch(raws)
    return _temperature_blocks(len(raws), _cdr_blocks(raws, TEMPERATURE_FLOATS, TEMPERATURE_NAME))


def decode_imu_ros1(
    raws: Sequence[RawMessage] | Spans, *, header_seq: bool | None = None
) -> ImuBatch:
    """Decode ROS 1 serialized ``sensor_msgs/Imu`` messages.

    Parameters
    ----------
    raws : sequence of bytes-like, or Spans, length N
        Serialized messages (ROS 1 bag record data).
    header_seq : bool, optional
        Whether the Header has ``uint32 seq`` (ROS 1 ``std_msgs/Header``: True; bags written
        with ROS 2 types, e.g. by ``fog_temp_comp.bag.bagio``: False). Take it from the
        connection's message definition with :func:`ros1_header_has_seq`. None: infer from the
        message lengths, and raise if both layouts fit.

    Returns
    -------
    ImuBatch
        N messages, in input order, with ``seq`` when the Header has it.

    Raises
    ------
    ValueError
        A message does not have the length its frame_id implies (truncated, trailing bytes,
        wrong ``header_seq``), or a frame_id is not UTF-8.

    """
    raws = _as_batch(raws)
    return _imu_blocks(len(raws), _ros1_blocks(raws, IMU_FLOATS, IMU_NAME, header_seq))


def decode_temperature_ros1(
    raws: Sequence[RawMessage] | Spans, *, header_seq: bool | None = None
) -> TemperatureBatch:
    """Decode ROS 1 serialized ``sensor_msgs/Temperature``; see :func:`decode_imu_ros1`.

    Parameters
    ----------
    raws : sequence of bytes-like, or Spans, length N
        Serialized messages.
    header_seq : bool, optional
        Whether the Header has ``uint32 seq``; None infers it.

    Returns
    -------
    TemperatureBatch
        N messages, in input order.

    """
    raws = _as_batch(raws)
    blocks = _ros1_blocks(raws, TEMPERATURE_FLOATS, TEMPERATURE_NAME, header_seq)
    return _temperature_blocks(len(raws), blocks)


_SEQ_LINE = re.compile(r'^\s*uint32\s+seq\b', re.MULTILINE)


def ros1_header_has_seq(msgdef: str) -> bool:
    """Whether a ROS 1 message definition's ``std_msgs/Header`` has ``seq``.

    Parameters
    ----------
    msgdef : str
        Full message definition of a ROS 1 connection (``connection.msgdef.data`` in rosbags),
        with the ``MSG: std_msgs/Header`` section.

    Returns
    -------
    bool
        True for a standard ROS 1 Header (or when the definition has no Header section), False
        for a Header of ``time stamp`` and ``string frame_id`` only (ROS 2 types in a ROS 1
        bag, as ``fog_temp_comp.bag.bagio`` writes them).

    """
    match = re.search(r'^MSG:\s*std_msgs/(?:msg/)?Header\s*$', msgdef, re.MULTILINE)
    if match is None:
        return True
    section = re.split(r'^={10,}\s*$', msgdef[match.end() :], maxsplit=1, flags=re.MULTILINE)[0]
    return _SEQ_LINE.search(section) is not None


def decode_numbers(
    raws: Sequence[RawMessage] | Spans, msgtype: str, *, ros1: bool = False
) -> FloatArray:
    """The ``data`` of serialized ``std_msgs/Float64`` or ``Float32`` messages, shape (N,).

    ``raws``: :class:`Spans` or a list of byte buffers, CDR (a
    4-byte encapsulation header, either byte order) or ROS 1 (``ros1``: the bare number).
    Raises ValueError on a message of another size or an unknown encapsulation.
    """
    spans = raws if isinstance(raws, Spans) else Spans.join(list(raws))
    size = 8 if msgtype == 'std_msgs/msg/Float64' else 4
    offset = 0 if ros1 else 4
    if np.any(spans.lengths < offset + size):
        raise ValueError(f'{msgtype}: a message shorter than {offset + size} bytes')
    buffer = np.frombuffer(spans.buffer, dtype=np.uint8)
    starts = np.asarray(spans.starts, dtype=np.int64)
    data = buffer[(starts + offset)[:, None] + np.arange(size)]
    little = np.ones(starts.size, dtype=bool)
    if not ros1:  # CDR_BE 0x0000, CDR_LE 0x0001
        kind = buffer[starts + 1]
        if np.any(buffer[starts] != 0) or np.any(kind > 1):
            raise ValueError(f'{msgtype}: not a plain CDR encapsulation')
        little = kind == 1
    dtype = np.dtype(f'f{size}')
    values = np.empty(starts.size, dtype=np.float64)
    values[little] = data[little].copy().view(dtype.newbyteorder('<')).ravel()
    values[~little] = data[~little].copy().view(dtype.newbyteorder('>')).ravel()
    return values
